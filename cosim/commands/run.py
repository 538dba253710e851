"""``cosim run``: run a scenario in closed loop with a plant FMU and a controller."""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from cosim.isolated import DEFAULT_STEP_TIMEOUT

#: The project's plant FMU (built on first use), whatever the current folder.
DEFAULT_PLANT = Path(__file__).resolve().parents[2] / "fmus" / "FourTank.fmu"

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
  timings.csv   wall-clock diagnostics of the controller (solve times), when it has any

Nothing is lost when a run is stopped. Rows stream into DIR/results.csv.part as the run goes
(flushed at least once a second) and become results.csv when the run ends: a run killed
outright (SIGKILL, power loss) leaves its rows in results.csv.part. If the FMU or the
controller fails, or Ctrl-C, SIGTERM or SIGHUP arrives, everything recorded so far is written
with the summary (status failed or interrupted). Every file is written to a temporary file and
renamed into place: a full disk leaves the previous file intact. A rerun into the same DIR
replaces the earlier run's files and removes those it does not write again; a second run into
a DIR that a run is still writing is refused.

A plant FMU is native code: use --isolate so that a crashing FMU cannot take the runner down,
and --step-timeout so that a hung one is stopped (it implies --isolate).
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

exit codes: 0 ok, 1 run failed mid-way (partial results kept) or an output could not be
written, 2 bad input (nothing run), 130 / 143 / 129 interrupted by SIGINT (Ctrl-C) / SIGTERM /
SIGHUP (partial results kept)"""


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
                        "cleanly instead of killing it); its steps time out after "
                        f"{DEFAULT_STEP_TIMEOUT:g} s unless --step-timeout says otherwise")
    p.add_argument("--step-timeout", metavar="SECONDS", type=float, default=None,
                   help="fail the run when one plant step or one controller step takes "
                        "longer than this (wall clock); implies --isolate, and the hung "
                        "worker is killed")
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


def _step_timeout(args: argparse.Namespace) -> float | None:
    """The plant/controller step limit: --step-timeout, else the isolated default."""
    import math

    from cosim.errors import CosimError

    limit = args.step_timeout
    if limit is None:
        return DEFAULT_STEP_TIMEOUT if args.isolate else None
    if not (math.isfinite(limit) and limit > 0):
        raise CosimError(f"--step-timeout {limit!r}: expected a positive number of seconds")
    return float(limit)


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim run``; returns the exit code (raises CosimError/SimulationFailed)."""
    from cosim import interrupts, outpaths, registry, results, scenario, varmap
    from cosim.errors import EXIT_OK, CosimError, SimulationFailed
    from cosim.master import Master, communication_times
    from cosim.runfolder import RunFolder

    sc = scenario.load(args.scenario)
    vmap = varmap.load(args.map) if args.map else None
    plant_path = _plant_path(args.plant)
    step_timeout = _step_timeout(args)
    isolate = bool(args.isolate or args.step_timeout is not None)
    ctrl_name = args.controller or registry.DEFAULT
    options = registry.parse_options(args.option)
    if args.model is not None:
        options["model"] = args.model
    out = Path(args.out) if args.out else Path("results") / sc.path.stem
    outpaths.out_dir(out, "--out")
    controller = registry.create(ctrl_name, options)
    if isolate:
        from cosim.isolated import IsolatedFmuComponent

        plant = IsolatedFmuComponent(plant_path, name="plant", interface=args.interface,
                                     varmap=vmap, timeout=step_timeout)
    else:
        from cosim.fmu import FmuComponent

        plant = FmuComponent(plant_path, name="plant", interface=args.interface, varmap=vmap)
    master = Master(plant, controller, sc, step=args.step, seed=args.seed)
    meta = {"scenario": str(sc.path), "plant": str(plant_path),
            "fmi_version": plant.fmi_version, "interface": args.interface,
            "isolated": isolate, "step_timeout": step_timeout,
            "map": str(args.map) if args.map else None, "controller": ctrl_name,
            "controller_options": options, "seed": args.seed}

    guard = interrupts.current()
    with RunFolder(out, "--out") as folder, \
            guard.deferred() if guard is not None else contextlib.nullcontext():
        # signals raise only inside the master's step loop; around it (set-up, writing the
        # results) they are recorded and acted on once everything is on disk
        stream = results.ResultsStream(folder.path / "results.csv")
        bar = _progress_bar(args, sc, master, communication_times)
        try:
            result = master.run(on_step=None if bar is None else lambda k: bar.update(1),
                                record=stream, step_timeout=step_timeout)
        except BaseException:
            stream.close()
            raise
        finally:
            if bar is not None:
                bar.close()
        if (not result.rows and isinstance(result.error, CosimError)
                and not isinstance(result.error, SimulationFailed)):
            raise result.error  # bad input found while loading the FMU: nothing was run
        doc = results.write(folder.path, result, meta, figure=not args.no_figure,
                            stream=stream)
    if result.error is not None:
        if isinstance(result.error, KeyboardInterrupt):
            raise result.error
        raise SimulationFailed(f"{result.reason} (partial results: {result.steps} of "
                               f"{result.steps_planned} steps in {out})")
    if guard is not None:
        guard.check()  # a signal that arrived while the results were written
    if not args.quiet:
        k = doc["kpis"]
        iae = ", ".join(f"{o}={v:.4g}" for o, v in k["iae"].items())
        viol = sum(v["count"] for v in k["violations"].values())
        print(f"cosim run: ok: {result.steps} steps in {result.wall_time_s:.2f} s; IAE {iae} "
              f"m·s; {viol} constraint violations; results in {out}")
    return EXIT_OK


def _progress_bar(args: argparse.Namespace, sc: object, master: object,
                  communication_times: object) -> object:
    """A tqdm bar over the plant steps on an interactive terminal, else ``None``."""
    if args.quiet or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    total = len(communication_times(sc.start_time, sc.stop_time, master.dt)) - 1
    return tqdm(total=total, unit="step", desc=sc.path.stem, file=sys.stderr,
                dynamic_ncols=True)
