"""Check the tracking law's convergence claims on a finished ``tracking_theorem`` campaign.

    cosim campaign scenarios/campaigns/tracking_theorem.toml
    python examples/tracking_theorem.py results/campaigns/tracking-theorem

For every run and set-point interval of the campaign (docs/design/tracking.md, claims 3-4):

- the target the law was given at the end of the interval, ``r = ȳ − d̂``, and the steady
  output it settled on, ``y_s`` (``ctrl.y_model_<output>``, ``ctrl.d_hat_<output>``);
- **closest admissible steady state**: ``y_s`` lies in ``Y_s`` and is no farther from ``r``
  than the closest of a dense grid of admissible steady outputs (``‖u‖∞ ≤ 1``, in ``Y_s``),
  within ``--tol``;
- **offset-free**: where ``r`` itself is an admissible steady output (``y_s`` within 1 mm of
  ``r``), the measured output's mean over the interval's last 50 samples is within the noise
  of ``ȳ`` (``--noise-tol``).

Prints one line per claim, the number of intervals that hold it, and the worst interval;
exit status 1 when an interval fails a claim.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def steady_output_grid(model, points: int) -> np.ndarray:
    """Steady outputs ``g(x_s(u))`` on a ``points^m`` grid over ``‖u‖∞ ≤ 1`` (normalised)."""
    from controllers.gru import output
    from controllers.ocp.steady_state import steady_state

    m = model.m
    axes = [np.linspace(-1.0, 1.0, points)] * m
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    x = np.zeros(model.n)
    out = []
    for u in grid:
        xs, _, ok = steady_state(model.params, u, x)
        if ok:
            x = xs
            out.append(output(model.params, xs))
    return np.array(out)


def intervals(folder: Path, points: int = 81) -> pd.DataFrame:
    """One row per run and set-point interval of the campaign in ``folder``: ``in_Ys``
    (largest row of ``L y_s − rhs``), ``excess`` (how much farther ``y_s`` is from ``r`` than
    the grid's closest admissible steady output), ``reached`` (``y_s`` within 1 mm of ``r``)
    and ``offset`` (the measured output's mean over the last 50 samples against ``ȳ``)."""
    from cosim.adapters.robust_mpc import RobustMPCController
    from cosim.campaign import load

    spec = load(json.loads((folder / "campaign.json").read_text())["spec_file"])
    if not (spec.plant or "").startswith("model:"):
        raise SystemExit(f"{folder}: not a campaign with a GRU-model plant")
    ctrl = RobustMPCController(law="tracking", model=spec.plant.removeprefix("model:"),
                               **{k: v for k, v in spec.options.items() if k != "law"})
    model, fh = ctrl.mpc.model, ctrl.mpc.fhocp
    names = list(ctrl.problem.output_names)
    rhs = fh.reference.ys_bounds
    Y = steady_output_grid(model, points)
    Y = Y[np.all(rhs + 1e-12 >= Y @ fh.L.T, axis=1)]          # admissible steady outputs
    scale = np.abs(model.y_scale)
    rows = []
    for run in sorted((folder / "runs").iterdir()):
        res = pd.read_csv(run / "results.csv")
        summary = json.loads((run / "summary.json").read_text())
        starts = [t for t, _ in summary["campaign"]["setpoints"]] + [float("inf")]
        for a, b in itertools.pairwise(starts):
            seg = res[(res.time >= a) & (res.time < b)]
            last = seg.iloc[-50:]
            y_ref = model.normalize_y(np.array([seg[f"ref.{n}"].iloc[-1] for n in names]))
            d_hat = np.array([seg[f"ctrl.d_hat_{n}"].iloc[-1] for n in names]) / scale
            y_s = model.normalize_y(np.array([seg[f"ctrl.y_model_{n}"].iloc[-1]
                                              for n in names]))
            r = y_ref - d_hat
            best = float(np.min(np.linalg.norm(Y - r, axis=1)))
            meas = np.array([last[f"sensor.{n}"].mean() for n in names])
            rows.append({
                "run": run.name, "start": a,
                "in_Ys": float(np.max(fh.L @ y_s - rhs)),
                "excess": float(np.linalg.norm(y_s - r) - best) * float(np.max(scale)),
                "reached": bool(np.max(np.abs(y_s - r)) * np.max(scale) < 1e-3),
                "offset": float(np.max(np.abs(meas - model.denormalize_y(y_ref)))),
            })
    return pd.DataFrame(rows)


def claims(df: pd.DataFrame, tol: float, noise_tol: float) -> list[tuple[str, int, int, float]]:
    """``(claim, intervals holding it, intervals checked, worst value)`` per claim."""
    reached = df[df.reached]
    out = []
    for label, ok, worst in (
            ("y_s in Y_s", df.in_Ys <= 1e-7, df.in_Ys.max()),
            (f"y_s the closest admissible steady output (within {tol:g})", df.excess <= tol,
             df.excess.max()),
            (f"offset-free where r is admissible (within {noise_tol:g})",
             reached.offset <= noise_tol, reached.offset.max() if len(reached) else 0.0)):
        out.append((label, int(ok.sum()), len(ok), float(worst)))
    return out


def check(folder: Path, points: int, tol: float, noise_tol: float) -> int:
    """Print the claims' counts; 1 when an interval fails one."""
    df = intervals(folder, points)
    bad = 0
    for label, held, total, worst in claims(df, tol, noise_tol):
        print(f"{label}: {held} / {total} intervals, worst {worst:.3g}")
        bad += total - held
    print(f"{len(df)} intervals in {df.run.nunique()} runs")
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path, help="the campaign's output folder")
    p.add_argument("--points", type=int, default=81, help="grid points per input (81)")
    p.add_argument("--tol", type=float, default=2e-3,
                   help="how much farther from r than the grid's best y_s may be (2 mm)")
    p.add_argument("--noise-tol", type=float, default=0.02,
                   help="measured offset allowed where r is admissible (20 mm: about 5 sigma of "
                        "the mean of 50 samples of ±5 cm uniform noise)")
    a = p.parse_args(argv)
    return check(a.folder, a.points, a.tol, a.noise_tol)


if __name__ == "__main__":
    sys.exit(main())
