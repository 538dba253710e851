"""``cosim tune``: the robust MPC's cost weights chosen on the model, as the PI is tuned from it."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.errors import exit_codes_help

__all__ = ["CANDIDATES", "DESCRIPTION", "HELP", "choose", "hint", "register", "run",
           "scenario"]

HELP = "choose the robust MPC's cost weights on the model itself, against the PI tuned from it"

DESCRIPTION = """\
Run the robust MPC (its tracking law) with a few cost weightings, and the PI baseline tuned
from the same model, in closed loop with the GRU model itself as the plant (no FMU needed) on
a set-point scenario: --scenario, else steps between four steady outputs of the model, each
held six of its slowest time constants, with Gaussian sensor noise whose standard deviation
is the model's measured one-step prediction error (its 95th percentile, else the largest
error w_y_bar: an upper estimate of the sensors' noise, so that a weighting that passes the
noise on to the inputs loses where the data were noisy). Choose the weighting with the
lowest summed IAE (each output's IAE over its box width) among those without constraint
violations whose input total variation is at most --tv-ratio times the PI's (default 1.2);
none: the defaults. A plant that is not square has no PI baseline: the defaults are the
reference then.

The candidates, in normalised units: the defaults (Q = I, R = 0.01 I, S = 0.05); the stage
cost on the outputs (Q = "outputs"); the same with light input weights (R = 0.001, S =
0.01); and without the input-rate weight (R = 0.001, S = 0), fast where the sensors are
clean. --save writes the choice into the model file's problem as its [mpc] table
(atomically: a failed write leaves the file as it was), which every later run of the model
uses under its own --option values (a --problem file with an [mpc] table replaces it).

examples:
  cosim tune models/plant_gru.json                      # the table, nothing written
  cosim tune models/plant_gru.json --save               # and the choice into the model
  cosim tune models/plant_gru.json --scenario steps.csv --tv-ratio 1.0"""

#: The weightings tried (robust-MPC options; ``Q``, ``R``, ``du_weight`` in normalised units).
CANDIDATES: dict[str, dict[str, Any]] = {
    "defaults": {"Q": 1.0, "R": 0.01, "du_weight": 0.05},
    "output cost": {"Q": "outputs", "R": 0.01, "du_weight": 0.05},
    "output cost, light inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.01},
    "output cost, free inputs": {"Q": "outputs", "R": 0.001, "du_weight": 0.0},
}
#: Where the inputs are held for the generated scenario's set-points (fractions of each
#: input's box; input j takes the pattern shifted by j).
PATTERN = (0.3, 0.7, 0.5, 0.2)
#: A contraction rate of the certificate (``rho_s``, ``lem:Vs``) above which a tuning that
#: does not beat the PI points at the training (:func:`hint`).
RHO_HINT = 0.99
#: Hold of each generated set-point: this many of the model's slowest time constants, within
#: these bounds [samples].
HOLD_TIME_CONSTANTS, HOLD_MIN, HOLD_MAX = 6.0, 20, 300


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``tune`` sub-command."""
    p = subparsers.add_parser("tune", help=HELP, description=DESCRIPTION,
                              epilog=exit_codes_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.json", help="GRU model file with its problem")
    p.add_argument("--scenario", metavar="CSV", default=None,
                   help="set-point scenario to tune on (default: generated from the model)")
    p.add_argument("--tv-ratio", type=float, default=1.2, dest="tv_ratio",
                   help="largest input total variation allowed, times the PI's (default 1.2)")
    p.add_argument("--save", action="store_true",
                   help="write the choice into the model file's problem ([mpc])")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def scenario(model: Any, path: Path) -> Path:
    """Write the generated scenario (module docstring) of ``model`` to ``path``."""
    from controllers.equilibrium import equilibrium_output, jacobians

    problem, params = model.problem, model.params
    lo, hi = np.array(problem.output_bounds).T
    targets, slowest = [], 0.0
    for k in range(len(PATTERN)):
        u = np.array([c.min + PATTERN[(k + j) % len(PATTERN)] * (c.max - c.min)
                      for j, c in enumerate(problem.inputs)])
        un = model.normalize_u(u)
        x, y = equilibrium_output(params, un)
        rho = float(np.max(np.abs(np.linalg.eigvals(jacobians(params, x, un)[0]))))
        slowest = max(slowest, -1.0 / math.log(min(max(rho, 1e-12), 1.0 - 1e-12)))
        targets.append(np.clip(model.denormalize_y(y), lo + 0.05 * (hi - lo),
                               hi - 0.05 * (hi - lo)))
    hold = int(min(max(math.ceil(HOLD_TIME_CONSTANTS * slowest), HOLD_MIN), HOLD_MAX))
    noise = _noise(model)
    names = problem.output_names
    header = ["time", *(f"ref.{o}" for o in names), *(f"sensor.{o}.noise" for o in names)]
    rows = [",".join(header)]
    for k, y in enumerate(targets):
        first = [f"{v:.6g}" for v in noise] if k == 0 else [""] * len(names)
        rows.append(",".join([f"{k * hold * problem.Ts:g}", *(f"{v:.6g}" for v in y),
                              *first]))
    rows.append(",".join([f"{len(targets) * hold * problem.Ts:g}"] + [""] * (2 * len(names))))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def _noise(model: Any) -> np.ndarray:
    """Sensor noise std per output [its unit]: the measured one-step prediction error (its
    95th percentile, :mod:`controllers.certification.prediction_error`), else ``w̄_y``, else
    none; an upper estimate on purpose (module docstring)."""
    profile = model.prediction_error
    if profile is not None and len(profile) > 1:
        err = np.asarray(profile[1], dtype=float)
    elif model.w_y_bar is not None:
        err = np.full(model.p, float(model.w_y_bar))
    else:
        err = np.zeros(model.p)
    return err * np.abs(np.asarray(model.y_scale, dtype=float))


def _score(summary: dict[str, Any]) -> dict[str, float]:
    """Summed IAE (each over its output's box width), summed input TV (each over its box
    width) and the violations of a run's summary."""
    k, sig = summary["kpis"], summary["signals"]
    width = {**{o: s["max"] - s["min"] for o, s in sig["outputs"].items()},
             **{u: s["max"] - s["min"] for u, s in sig["inputs"].items()}}
    return {"iae": sum(v / width[o] for o, v in k["iae"].items()),
            "tv": sum(v / width[u] for u, v in k["tv"].items()),
            "violations": sum(v["count"] for v in k["violations"].values())}


def choose(rows: dict[str, dict[str, float]], tv_ratio: float) -> str:
    """The candidate of ``rows`` (name → :func:`_score` ratios to the PI: ``iae``, ``tv``,
    ``violations``) with the lowest IAE within the TV bound and without violations, else
    ``"defaults"``."""
    ok = [n for n, r in rows.items() if r["violations"] == 0 and r["tv"] <= tv_ratio]
    return min(ok, key=lambda n: rows[n]["iae"]) if ok else "defaults"


def hint(model: Any, rows: dict[str, dict[str, float]], best: str) -> str | None:
    """What to do when no weighting beats the PI on the model (``None`` when one does): with
    a slow certified contraction, the terminal weight ``s = n λ_max(Q) / (1 − ρ_s²)``
    (``eq:definition_s``) makes every horizon's end costly, and only a model trained to
    contract faster lowers it (docs: design/tracking.md, "Other plants")."""
    if rows[best]["iae"] < 1.0:
        return None
    from controllers.certification.certificates import compute_certificate
    from cosim_adapters.mpc_options import MPCOptions
    from cosim_adapters.robust_mpc import design_arguments

    text = f"no weighting beats the PI on the model (the best: {rows[best]['iae']:.2f}x its IAE)"
    options = MPCOptions.resolve({"law": "tracking", **CANDIDATES[best]}, model.problem)
    cert = compute_certificate(model, gain_scale=0.0, **design_arguments(options, model))
    if cert.rho_s > RHO_HINT:
        text += (f": the certified terminal weight s = {cert.s:,.0f} (rho_s = "
                 f"{cert.rho_s:.4f}) makes ending a horizon away from the steady state costly, "
                 "so every weighting approaches it slowly; a model trained to contract faster "
                 "has a smaller one: cosim train --sigma-z-max 0.9 (or [train] sigma_z_max = "
                 "0.9 in the problem file)")
    return text


def run(args: argparse.Namespace) -> int:
    """Run the candidates and the PI on the model, print the table, save the choice."""
    import sys
    import tempfile

    from tqdm import tqdm

    import cosim
    from controllers.errors import ControllersError
    from controllers.model import GRUModel
    from cosim.core.errors import CosimError, SimulationFailed

    if not (math.isfinite(args.tv_ratio) and args.tv_ratio > 0):
        raise CosimError(f"--tv-ratio must be a positive number, got {args.tv_ratio}")
    try:
        model = GRUModel.load(args.model)
    except ControllersError as exc:
        raise CosimError(str(exc)) from None
    if model.problem is None:
        raise CosimError(f"{args.model}: the model file has no control problem (train it "
                         "with 'cosim train --problem')")
    with tempfile.TemporaryDirectory(prefix="cosim-tune-") as tmp:
        sc = Path(args.scenario) if args.scenario else scenario(model, Path(tmp) / "steps.csv")
        plant = f"model:{args.model}"
        results = {}
        square = model.problem.m == model.problem.p
        runs = {"pi": None, **CANDIDATES} if square else dict(CANDIDATES)
        bar = tqdm(runs.items(), desc="tune", unit="run", file=sys.stderr,
                   disable=args.quiet or not sys.stderr.isatty(), dynamic_ncols=True)
        for name, options in bar:
            controller = "pi" if options is None else "robust-mpc"
            opts = {"law": "tracking", **options} if options is not None else {}
            out = cosim.run(sc, plant=plant, controller=controller, model=args.model,
                            options=opts, seed=0)
            if out.status != "ok":
                raise SimulationFailed(f"{name}: the run {out.status}: {out.reason}")
            results[name] = _score(out.summary)
    base = results.pop("pi") if square else results["defaults"]   # no PI: not square
    rows = {n: {"iae": r["iae"] / base["iae"],
                "tv": r["tv"] / base["tv"] if base["tv"] else 0.0,
                "violations": r["violations"]} for n, r in results.items()}
    best = choose(rows, args.tv_ratio)
    against = "pi" if square else "defaults"
    advice = hint(model, rows, best) if square else None
    if args.json:
        print(json.dumps({"candidates": rows, "chosen": best, "against": against,
                          "options": CANDIDATES[best], "hint": advice}, indent=1))
    elif not args.quiet:
        _print(args, sc if args.scenario else None, rows, best, against)
        if advice:
            print(f"cosim tune: hint: {advice}")
    if args.save:
        _save(Path(args.model), model, CANDIDATES[best])
        if not args.quiet and not args.json:
            print(f"cosim tune: {args.model}: [mpc] {_toml(CANDIDATES[best])}")
    return 0


def _print(args: argparse.Namespace, sc: Path | None, rows: dict[str, dict[str, float]],
           best: str, against: str) -> None:
    where = f"scenario {sc}" if sc else "the model's own steps"
    of = "the PI's" if against == "pi" else "the defaults' (no PI: not a square plant)"
    print(f"{args.model} as the plant, {where}; summed IAE and input TV ÷ {of}:")
    for name, r in rows.items():
        mark = "  <- chosen" if name == best else ""
        print(f"  {name:28s} IAE {r['iae']:.3f}  TV {r['tv']:.3f}  violations "
              f"{r['violations']}{mark}")


def _toml(options: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {json.dumps(v)}" for k, v in options.items())


def _save(path: Path, model: Any, options: dict[str, Any]) -> None:
    """The model file with ``options`` over its problem's ``[mpc]`` table (atomic: a failed
    write leaves it as it was)."""
    import dataclasses

    from cosim.core.atomicio import output_error

    model.problem = dataclasses.replace(model.problem, mpc={**model.problem.mpc, **options})
    try:
        model.save(path)
    except OSError as exc:
        raise output_error(path, exc) from None
