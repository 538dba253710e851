"""``cosim run``: run a scenario in closed loop with a plant FMU and a controller."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_PLANT = Path("fmus/FourTank.fmu")

DESCRIPTION = """\
Run a scenario in closed loop: the plant FMU and the controller are stepped in lockstep at a
fixed communication step (default: the controller's sample time), driven by the scenario's
set-points and perturbations. Writes into DIR (--out):

  results.csv   time first, one column per signal (ref.*, plant.*, sensor.*, ctrl.*),
                FMI cross-check CSV conventions, full float precision
  summary.json  status (ok/failed/interrupted), reason, steps, KPIs (IAE per output,
                constraint violations, control effort), controller solver statistics
  figure.png    outputs vs set-points with constraint bounds, inputs with bounds,
                perturbation times marked

If the FMU fails or crashes mid-run, everything recorded up to the fault is written and the
command exits with status 1; use --isolate so that a crashing FMU cannot take the runner down.
"""

EPILOG = """\
scenario CSV: time,ref.<output>,plant.<variable>,sensor.<output>.bias,sensor.<output>.noise
  piecewise constant; a blank cell keeps the previous value; the last row's time is the
  stop time (see the README, section "Scenarios").

examples:
  cosim run scenarios/paper_steps.csv
  cosim run scenarios/leak_tank1.csv --controller pi --out results/leak --quiet
  cosim run scenarios/paper_steps.csv --plant other.fmu --map other.map.toml --isolate
  cosim run scenarios/paper_steps.csv --model my_gru.json --option offset_free=true

exit codes: 0 ok, 1 run failed mid-way (partial results kept), 2 bad input, 130 interrupted"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``run`` sub-command."""
    p = subparsers.add_parser(
        "run", help="run a scenario in closed loop (plant FMU + controller)",
        description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", metavar="SCENARIO", help="scenario CSV file")
    p.add_argument("--plant", metavar="FMU", default=None,
                   help=f"plant FMU, FMI 2.0 or 3.0 (default: {DEFAULT_PLANT}, built if "
                        "missing)")
    p.add_argument("--map", metavar="MAP", default=None,
                   help="variable map TOML for a plant whose variable names or units differ "
                        "(checked against its modelDescription before the first step)")
    p.add_argument("--controller", metavar="NAME", default=None,
                   help="controller: 'robust-mpc' (default), 'pi', or module:Class")
    p.add_argument("--model", metavar="FILE", default=None,
                   help="GRU model file for the robust MPC (default: the shipped "
                        "controllers/models/fourtank_gru.json); same as --option model=FILE")
    p.add_argument("--option", metavar="KEY=VALUE", action="append", default=[],
                   help="controller constructor option, repeatable; VALUE is read as JSON "
                        "when it parses (e.g. --option setpoint_rate=0.02 --option "
                        "offset_free=true --option N=20)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="output folder (default: results/<scenario name>)")
    p.add_argument("--interface", choices=("cs", "me"), default="cs",
                   help="FMI interface: cs = Co-Simulation (default), me = Model Exchange "
                        "with fmpy's CVode")
    p.add_argument("--step", metavar="SECONDS", type=float, default=None,
                   help="communication step (default: the controller's sample time; must "
                        "divide it)")
    p.add_argument("--isolate", action="store_true",
                   help="run the FMU in a worker process (a crashing FMU fails the run "
                        "cleanly instead of killing it)")
    p.add_argument("--seed", metavar="N", type=int, default=0,
                   help="seed of the measurement noise (default 0)")
    p.add_argument("--no-figure", action="store_true", help="do not draw figure.png")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar and no summary line (for scripts)")
    p.set_defaults(func=run)


def _plant_path(arg: str | None) -> Path:
    from cosim.errors import CosimError

    if arg is not None:
        path = Path(arg)
        if path.is_dir():
            raise CosimError(f"{path}: is a folder, not an FMU file (.fmu zip archive)")
        if not path.is_file():
            raise CosimError(f"{path}: FMU not found")
        return path
    if not DEFAULT_PLANT.is_file():
        try:
            from cosim.build import build_fmus
        except ImportError:
            raise CosimError(f"{DEFAULT_PLANT} not found and cannot be built here; run "
                             "'cosim build-fmu' or give --plant") from None
        build_fmus()
        if not DEFAULT_PLANT.is_file():
            raise CosimError(f"{DEFAULT_PLANT}: not produced by cosim build-fmu")
    return DEFAULT_PLANT


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim run``; returns the exit code (raises CosimError/SimulationFailed)."""
    from cosim import outpaths, registry, results, scenario, varmap
    from cosim.errors import EXIT_OK, CosimError, SimulationFailed
    from cosim.master import Master, communication_times

    sc = scenario.load(args.scenario)
    vmap = varmap.load(args.map) if args.map else None
    plant_path = _plant_path(args.plant)
    ctrl_name = args.controller or registry.DEFAULT
    options = registry.parse_options(args.option)
    if args.model is not None:
        options["model"] = args.model
    controller = registry.create(ctrl_name, options)
    if args.isolate:
        from cosim.isolated import IsolatedFmuComponent as Plant
    else:
        from cosim.fmu import FmuComponent as Plant
    plant = Plant(plant_path, name="plant", interface=args.interface, varmap=vmap)
    master = Master(plant, controller, sc, step=args.step, seed=args.seed)
    out = Path(args.out) if args.out else Path("results") / sc.path.stem
    outpaths.out_dir(out, "--out")

    show = not args.quiet and sys.stderr.isatty()
    bar = None
    on_step = None
    if show:
        from tqdm import tqdm

        total = len(communication_times(sc.start_time, sc.stop_time, master.dt)) - 1
        bar = tqdm(total=total,
                   unit="step", desc=sc.path.stem, file=sys.stderr, dynamic_ncols=True)

        def on_step(k: int) -> None:
            bar.update(1)

    try:
        result = master.run(on_step=on_step)
    finally:
        if bar is not None:
            bar.close()
    if (not result.rows and isinstance(result.error, CosimError)
            and not isinstance(result.error, SimulationFailed)):
        raise result.error  # bad input found while loading the FMU: nothing was run
    meta = {"scenario": str(sc.path), "plant": str(plant_path),
            "fmi_version": plant.fmi_version, "interface": args.interface,
            "isolated": bool(args.isolate), "map": str(args.map) if args.map else None,
            "controller": ctrl_name, "controller_options": options, "seed": args.seed}
    doc = results.write(out, result, meta, figure=not args.no_figure)
    if result.error is not None:
        if isinstance(result.error, KeyboardInterrupt):
            raise result.error
        raise SimulationFailed(f"{result.reason} (partial results: {result.steps} of "
                               f"{result.steps_planned} steps in {out})")
    if not args.quiet:
        k = doc["kpis"]
        iae = ", ".join(f"{o}={v:.4g}" for o, v in k["iae"].items())
        viol = sum(v["count"] for v in k["violations"].values())
        print(f"cosim run: ok: {result.steps} steps in {result.wall_time_s:.2f} s; IAE {iae} "
              f"m·s; {viol} constraint violations; results in {out}")
    return EXIT_OK
