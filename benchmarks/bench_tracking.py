"""Tracking against the limit: the robust MPC, the PI baseline and an oracle NMPC.

In one process, on the paper scenario (``scenarios/paper_steps.csv``) with the four-tank plant
FMU (the default plant), four closed loops through :func:`cosim.run`:

* ``robust-mpc``: the shipped robust MPC, default options: the tracking law (the tracking
  FHOCP of issue 20: artificial steady state, offset-free, Δu terms, N = 80; its controller
  step, observer + FHOCP, timed in wall clock as ``bench_mpc.py`` does);
* ``paper``: the robust MPC with ``law="paper"`` (the paper's law with its reference
  governor, N = 15), timed the same way;
* ``pi``: the decentralised PI baseline;
* ``oracle``: the oracle NMPC of ``benchmarks/oracle_nmpc.py``: the plant's exact equations,
  its true state, no noise, no tightening, ``Q = I``, ``R = 0.01 I`` normalised, horizon
  ``--horizon`` samples, no terminal cost, the input box. A reference for this benchmark only.

Printed: per controller the IAE of each output, the summed IAE and the total variation of
each input (the project's KPIs, :mod:`cosim.core.kpis`: ``iae.<output>``, ``tv.<input>``), the
ratios of each MPC to the PI and to the oracle (issue 20 asks summed IAE MPC/PI ≤ 0.72 and TV
MPC/oracle ≤ 1.1 per input), each robust MPC's controller step median / p99, and the oracle's
solver health (failures, cold restarts, its model's one-sample prediction error against the
FMU).

Usage::

    .venv/bin/python benchmarks/bench_tracking.py [--horizon 80] [--out DIR] [--quick [SECONDS]]

``--out DIR`` writes each run's files (``DIR/<controller>/``: ``results.csv``,
``summary.json``, ``figure.png``), the table (``DIR/tracking.json``) and a figure comparing
them (``DIR/tracking.png``: outputs with their set-points, and inputs, one panel per
signal). ``--quick`` runs the first ``SECONDS`` (default 5000 s) of the scenario only.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE)]

import cosim  # noqa: E402
from cosim.adapters.robust_mpc import RobustMPCController  # noqa: E402
from cosim.core import kpis, results  # noqa: E402

SCENARIO = ROOT / "scenarios" / "paper_steps.csv"
#: The controllers compared, in the table's order: name → controller spec for ``cosim.run``.
CONTROLLERS = {"robust-mpc": "bench_tracking:TimedRobustMPC",
               "paper": "bench_tracking:TimedRobustMPC", "pi": "pi",
               "oracle": "oracle_nmpc:OracleNMPC"}
#: The robust MPCs (their controller steps timed): name → options.
MPC_OPTIONS = {"robust-mpc": {}, "paper": {"law": "paper"}}
#: The ratios printed: (label, numerator, denominator).
RATIOS = (("MPC/PI", "robust-mpc", "pi"), ("paper/PI", "paper", "pi"),
          ("oracle/PI", "oracle", "pi"), ("MPC/oracle", "robust-mpc", "oracle"),
          ("paper/oracle", "paper", "oracle"))
#: ``--quick`` without a number: the first two set-point changes of the paper scenario.
QUICK_SECONDS = 5000.0


class TimedRobustMPC(RobustMPCController):
    """The shipped robust MPC, its controller step timed (wall clock, as ``bench_mpc.py``)."""

    def setup(self, t0: float) -> None:
        """Reset the controller and the step times."""
        super().setup(t0)
        self.step_ms: list[float] = []

    def step(self, t: float, dt: float) -> None:
        """One controller step (observer + FHOCP, and the paper law's governor), timed."""
        t0 = time.perf_counter()
        super().step(t, dt)
        self.step_ms.append((time.perf_counter() - t0) * 1e3)

    def summary(self) -> dict:
        """The robust MPC's summary plus the step's median and p99 [ms]."""
        ms = np.asarray(self.step_ms or [np.nan])
        return {**super().summary(), "step_ms_median": float(np.median(ms)),
                "step_ms_p99": float(np.percentile(ms, 99))}


def scenario_file(quick: float | None, folder: Path) -> Path:
    """The paper scenario, or its first ``quick`` seconds written into ``folder``."""
    if quick is None:
        return SCENARIO
    with SCENARIO.open(newline="") as f:
        header, *rows = list(csv.reader(f))
    kept = [r for r in rows if float(r[0]) < quick]
    path = folder / f"paper_steps_{quick:g}s.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerows([header, *kept, [f"{quick:g}"] + [""] * (len(header) - 1)])
    return path


def run_one(name: str, scenario: Path, horizon: int, out: Path | None) -> cosim.api.RunOutput:
    """One closed loop; exits naming the controller when it does not finish."""
    options = {"horizon": horizon} if name == "oracle" else MPC_OPTIONS.get(name, {})
    t0 = time.perf_counter()
    run = cosim.run(scenario, controller=CONTROLLERS[name], options=options,
                    out=out / name if out is not None else None)
    run.meta["bench_wall_s"] = time.perf_counter() - t0
    if run.status != "ok":
        raise SystemExit(f"bench_tracking: {name}: the run {run.status}: {run.reason}")
    return run


def kpi_row(run: cosim.api.RunOutput) -> dict[str, float]:
    """``iae.<output>``, ``iae.sum``, ``tv.<input>`` (:func:`cosim.core.kpis.flat`)."""
    flat = kpis.flat(run.summary["kpis"])
    signals = run.summary["signals"]
    row = {f"iae.{o}": flat[f"iae.{o}"] for o in signals["outputs"] if f"iae.{o}" in flat}
    row["iae.sum"] = sum(row.values())
    row.update({f"tv.{u}": flat[f"tv.{u}"] for u in signals["inputs"]})
    return row


def ratio_rows(rows: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """The ratios of :data:`RATIOS`, KPI by KPI."""
    def ratio(a: float, b: float) -> float:
        return a / b if b != 0 else float("nan")

    return {label: {k: ratio(rows[num][k], rows[den][k]) for k in rows[num]}
            for label, num, den in RATIOS}


def format_table(rows: dict[str, dict[str, float]], ratios: dict[str, dict[str, float]],
                 wall: dict[str, float]) -> str:
    """The printed table: KPIs per controller, then the ratios."""
    keys = list(next(iter(rows.values())))
    lines = [f"{'':12s}" + "".join(f"{k:>11s}" for k in keys) + f"{'wall [s]':>11s}"]
    for name, row in rows.items():
        cells = "".join(f"{v:11.0f}" if k.startswith("iae") else f"{v:11.5f}"
                        for k, v in row.items())
        lines.append(f"{name:12s}{cells}{wall[name]:11.1f}")
    for label, row in ratios.items():
        lines.append(f"{label:12s}" + "".join(f"{v:11.4g}" for v in row.values()))
    return "\n".join(lines)


def health_lines(runs: dict[str, cosim.api.RunOutput]) -> list[str]:
    """The robust MPC's step time and solver statistics, the oracle's solver health."""
    orc = runs["oracle"].summary["controller_summary"]
    lines = []
    for name in MPC_OPTIONS:
        mpc = runs[name].summary["controller_summary"]
        lines.append(
            f"{name} controller step: median {mpc['step_ms_median']:.2f} ms, "
            f"p99 {mpc['step_ms_p99']:.2f} ms over {mpc.get('steps')} steps; solve failures "
            f"{mpc.get('failures')} {mpc.get('failures_by_status', '')}, fallbacks "
            f"{mpc.get('fallbacks')}, suboptimal {mpc.get('suboptimal_steps')}")
    return [*lines,
        f"oracle NMPC (N = {orc['horizon']}): {orc['failures']} failed solves, "
        f"{orc['cold_starts']} cold restarts, IPOPT iterations max {orc['iterations_max']}, "
        f"solve median {orc['solve_ms_median']:.1f} ms, p99 {orc['solve_ms_p99']:.1f} ms; "
        f"one-sample prediction vs the FMU: max {orc['prediction_error_max_m']:.1e} m",
    ]


def comparison_figure(runs: dict[str, cosim.api.RunOutput], path: Path) -> None:
    """Outputs with their set-points, then inputs, one panel per signal, every controller."""
    from cosim.core import plots

    signals = next(iter(runs.values())).summary["signals"]
    names = [("plant", o, u["unit"]) for o, u in signals["outputs"].items()] + \
        [("ctrl", i, u["unit"]) for i, u in signals["inputs"].items()]
    plt = plots.pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 2.4 * len(names)), sharex=True)
    for ax, (prefix, sig, unit) in zip(np.atleast_1d(axes), names, strict=True):
        for name, run in runs.items():
            df = run.to_pandas()
            ax.step(df["time"], df[f"{prefix}.{sig}"], where="post", lw=0.9, label=name)
        if prefix == "plant":
            df = next(iter(runs.values())).to_pandas()
            ax.step(df["time"], df[f"ref.{sig}"], where="post", color="k", ls="--", lw=0.8,
                    label="set-point")
        ax.set_ylabel(plots.label(sig, unit))
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(loc="upper left", ncol=4, fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    fig.tight_layout()
    plots.save(fig, path, dpi=110)


def write_results(out: Path, rows: dict, ratios: dict, runs: dict) -> None:
    """``tracking.json`` (KPIs, ratios, controller summaries) and ``tracking.png``."""
    doc = {"kpis": rows, "ratios": ratios,
           "wall_s": {n: r.meta["bench_wall_s"] for n, r in runs.items()},
           "controller_summary": {n: r.summary["controller_summary"] for n, r in runs.items()}}
    (out / "tracking.json").write_text(json.dumps(results.jsonable(doc), indent=2) + "\n")
    comparison_figure(runs, out / "tracking.png")


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--horizon", type=int, default=80, help="oracle NMPC horizon [samples]")
    ap.add_argument("--out", type=Path, help="folder for the runs, tracking.json and .png")
    ap.add_argument("--quick", type=float, nargs="?", const=QUICK_SECONDS, metavar="SECONDS",
                    help=f"first SECONDS of the scenario only (default {QUICK_SECONDS:g})")
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the four closed loops, print the table; 0 when all of them ran."""
    sys.modules.setdefault("bench_tracking", sys.modules[__name__])  # one TimedRobustMPC
    args = parse_args(argv)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        scenario = scenario_file(args.quick, Path(tmp))
        runs = {name: run_one(name, scenario, args.horizon, args.out) for name in CONTROLLERS}
    rows = {name: kpi_row(run) for name, run in runs.items()}
    ratios = ratio_rows(rows)
    wall = {name: run.meta["bench_wall_s"] for name, run in runs.items()}
    stop = runs["pi"].summary["stop_time"]
    print(f"scenario {SCENARIO.name} to t = {stop:g} s, oracle horizon {args.horizon}; "
          "IAE [m·s], TV [m³/s]")
    print(format_table(rows, ratios, wall))
    print("\n".join(health_lines(runs)))
    if args.out is not None:
        write_results(args.out, rows, ratios, runs)
        print(f"written: {args.out}/tracking.json, tracking.png, <controller>/")
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
