"""``cosim run``: run a scenario in closed loop with a plant FMU and a controller."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cosim.core.errors import exit_codes_help
from cosim.core.isolated import DEFAULT_STEP_TIMEOUT

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
  operator.csv  the operator's actions (op.* columns, faceplate writes): time, who, what,
                old, new, accepted or why refused
  controller.json  the controller and the options it was given, its model file
                fingerprinted: --controller controller.json runs the same controller again

Nothing is lost when a run is stopped. Rows stream into DIR/results.csv.part as the run goes
(flushed at least once a second) and become results.csv when the run ends: a run killed
outright (SIGKILL, power loss) leaves its rows in results.csv.part. If the FMU or the
controller fails, or Ctrl-C, SIGTERM or SIGHUP arrives, everything recorded so far is written
with the summary (status failed or interrupted). Every file is written to a temporary file and
renamed into place: a full disk leaves the previous file intact. A rerun into the same DIR
replaces the earlier run's files and removes those it does not write again; a second run into
a DIR that a run is still writing is refused.

With --hmi [HOST:]PORT the run's page is served while it runs (docs: "Watch it live"): a
panel per output (measured, set-point, limits, the MPC's prediction over its horizon and the
tightened constraint), per input, the status strip and the prediction error, pushed to the
browser; a user of --hmi-users logs in to change set-points and op.* settings (operator)
and the controller's settings (engineer), each request checked as an op.* cell or a
faceplate write, answered, and a row of DIR/operator.csv.

With --plant opc.tcp://HOST:PORT the plant is a live process: its control system's OPC UA
server (or cosim serve-plant), met on the wall clock, each sample read, stepped, written;
stale or implausible values, lost links, late steps and signals each have their answer,
written into the results (docs: "Run on a live process"); a live run that did not control the
plant (it never wrote an input, or wrote inputs computed from fresh data at less than
--min-controlled of its samples) exits 1.

An FMU is native code. A controller FMU always runs in a worker process of its own: a crash,
abort() or exit() in it fails the run (exit 1, partial results kept), a hung step is stopped
after 60 s (--step-timeout). Use --isolate so that the plant FMU and a Python controller run
in workers too, and --step-timeout so that a hung one is stopped sooner (it implies
--isolate). Ctrl-C and SIGTERM kill a worker stuck in native code at once.
"""

EPILOG = """\
scenario CSV: time,ref.<output>,plant.<variable>,sensor.<output>.bias|noise|uniform,
  op.<setting> (op.mode auto|manual, op.service.<input>, op.manual.<input>, op.min.<signal>, ...)
  piecewise constant; a blank cell keeps the previous value; the last row's time is the
  stop time (see docs/guide/running.md, "Scenarios").

examples:
  cosim run scenarios/paper_steps.csv
  cosim run scenarios/leak_tank1.csv --controller pi --out results/leak --quiet
  cosim run scenarios/paper_steps.csv --plant other.fmu --map other.map.toml --isolate
  cosim run scenarios/paper_steps.csv --model my_gru.json --option 'law="paper"'
  cosim run cstr_steps.csv --plant cstr.fmu --problem cstr.toml --controller pi
  cosim run scenarios/paper_steps.csv --plant opc.tcp://127.0.0.1:4840 --speed 100 \\
      --security None --watchdog 3 --problem problem_safe.toml --tags plc.tags.toml
  cosim run scenarios/paper_steps.csv --hmi 8050 --hmi-users users.toml

""" + exit_codes_help()


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``run`` sub-command."""
    p = subparsers.add_parser(
        "run", help="run a scenario in closed loop (plant FMU + controller)",
        description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", metavar="SCENARIO", help="scenario CSV file")
    _plant_arguments(p)
    _controller_arguments(p)
    _execution_arguments(p)
    _live_arguments(p)
    _operator_arguments(p)
    from cosim.commands import add_hmi_arguments

    add_hmi_arguments(p, "the run's page")
    p.add_argument("--no-figure", action="store_true", help="do not draw figure.png")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar and no summary line (for scripts)")
    p.set_defaults(func=run)


def _plant_arguments(p: argparse.ArgumentParser) -> None:
    """``--plant``, ``--map`` and ``--problem``: the plant and what binds it."""
    p.add_argument("--plant", metavar="FMU", default=None,
                   help="plant FMU, FMI 2.0 or 3.0 (default: the project's "
                        "FourTank.fmu, built if missing, see cosim build-fmu), or "
                        "model:FILE for the GRU model itself as the plant (the paper's "
                        "eq:perturbed-model; its "
                        "h1_start, h2_start, w_y_max, dx_<i> are scenario plant.* columns), "
                        "or opc.tcp://HOST:PORT: a live plant's OPC UA server (or cosim "
                        "serve-plant), on the wall clock")
    p.add_argument("--map", metavar="MAP", default=None,
                   help="variable map TOML for a plant whose variable names or units differ "
                        "(checked against its modelDescription before the first step)")
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="the control problem (signals, units, boxes, Ts): must be the "
                        "model's own when its file has one; default: the model's, else the "
                        "four-tank's (fmus/fourtank/problem.toml). The plant FMU is bound to "
                        "it: variables by name or the problem's 'variable' keys, units "
                        "converted, checked before the first step")


def _controller_arguments(p: argparse.ArgumentParser) -> None:
    """``--controller``, ``--model`` and ``--option``: the controller and its options."""
    p.add_argument("--controller", metavar="NAME", default=None,
                   help="controller: 'robust-mpc' (default), 'pi', module:Class, or a "
                        "controller file (FILE.json: the controller.json a run writes, its "
                        "options; --option overrides them)")
    p.add_argument("--model", metavar="FILE", default=None,
                   help="GRU model file for the robust MPC (default: the shipped "
                        "controllers/models/fourtank_gru.json); same as --option model=FILE")
    p.add_argument("--option", metavar="KEY=VALUE", action="append", default=[],
                   help="controller constructor option, repeatable; VALUE is read as JSON "
                        "when it parses (e.g. --option du_weight=0.5 --option N=40 "
                        "--option 'law=\"paper\"')")


def _execution_arguments(p: argparse.ArgumentParser) -> None:
    """Where the results go and how the loop runs: ``--out``, ``--interface``, ``--step``,
    ``--isolate``, ``--step-timeout``, ``--require-certificate``, ``--seed``."""
    p.add_argument("--out", metavar="DIR", default=None,
                   help="output folder (default: results/<scenario name>)")
    p.add_argument("--interface", choices=("cs", "me"), default="cs",
                   help="FMI interface: cs = Co-Simulation (default), me = Model Exchange "
                        "with fmpy's CVode")
    p.add_argument("--step", metavar="SECONDS", type=float, default=None,
                   help="communication step (default: the controller's sample time; must "
                        "divide it)")
    p.add_argument("--isolate", action="store_true",
                   help="run the plant FMU and a Python controller in worker processes (a "
                        "controller FMU always runs in one): a crash fails the run cleanly "
                        "instead of killing it; their steps time out after "
                        f"{DEFAULT_STEP_TIMEOUT:g} s unless --step-timeout says otherwise")
    p.add_argument("--step-timeout", metavar="SECONDS", type=float, default=None,
                   help="fail the run when one plant step or one controller step takes "
                        "longer than this (wall clock); implies --isolate, and the hung "
                        "worker is killed")
    p.add_argument("--require-certificate", action="store_true",
                   help="robust-mpc: refuse to run (exit 2) when the model is not certified "
                        "for this scenario's set-points, instead of running uncertified "
                        "(same as --option 'certificate=\"require\"')")
    p.add_argument("--seed", metavar="N", type=int, default=0,
                   help="seed of the measurement noise (default 0)")


def _live_arguments(p: argparse.ArgumentParser) -> None:
    """The options of a live plant (``--plant opc.tcp://...``): its tags, speed, watchdog
    and the connection's security."""
    live = p.add_argument_group("a live plant (--plant opc.tcp://HOST:PORT; docs: Run on a "
                                "live process)")
    live.add_argument("--tags", metavar="TAGS.toml", default=None,
                      help="map the problem's signals onto the plant's node ids or browse "
                           "paths (default: by name in the folder named for the problem)")
    live.add_argument("--speed", metavar="K", type=float, default=None,
                      help="the plant's speed-up: one sample every Ts/K seconds of the wall "
                           "clock (default 1; cosim serve-plant's --speed)")
    live.add_argument("--watchdog", metavar="N", type=int, default=None,
                      help="after N samples in a row without a fresh measurement, raise one "
                           "alarm line and write the problem's safe inputs (safe = VALUE), "
                           "again each sample until the plant reads them back")
    live.add_argument("--heartbeat", metavar="NODE", default=None,
                      help="write a counter to this node (a node id or browse path, as in a "
                           "tags file) every sample, so that the control system sheds the "
                           "controller when it stops")
    live.add_argument("--min-controlled", metavar="SHARE", type=float, default=None,
                      help="the least share of its samples at which the run must write "
                           "inputs computed from fresh data (default 0.5); a run below it, or "
                           "that never wrote an input, ends with exit 1")
    from cosim.live.security import add_arguments

    add_arguments(p, "client")


def _operator_arguments(p: argparse.ArgumentParser) -> None:
    """``--mode`` and the faceplate's options (docs: "Operating the controller")."""
    g = p.add_argument_group("the operator (docs: Operating the controller)")
    g.add_argument("--mode", choices=("auto", "manual"), default=None,
                   help="the controller's mode from the start: manual is the commissioning "
                        "in shadow (it writes nothing of its own, predicts against the plant; "
                        "op.mode in the scenario's first row)")
    g.add_argument("--faceplate", metavar="URL", default=None,
                   help="serve the controller's OPC UA faceplate at opc.tcp://127.0.0.1:PORT "
                        "while the run goes: mode, inputs in service and manual, outputs "
                        "controlled, operator limits, set-points, predictions; writes checked "
                        "as scenario rows and logged in operator.csv (same --security options "
                        "as --plant)")
    g.add_argument("--faceplate-users", metavar="USERS.toml", default=None,
                   help="the faceplate's users and roles (operator: mode, service, limits, "
                        "set-points; engineer: also the weights), each password read from the "
                        "environment variable its entry names; without: read-only")


#: The options of this command that name a library parameter (their errors are reworded).
FLAGS = ("seed", "step", "step_timeout", "mode")


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim run`` through :func:`cosim.api.run`; returns the exit code."""
    from cosim import api
    from cosim.commands import hmi_options
    from cosim.core import registry
    from cosim.core.errors import CosimError, ParameterError, SimulationFailed

    options = registry.parse_options(args.option)
    live = _live_options(args)
    hmi = hmi_options(args)
    if args.require_certificate:
        options["certificate"] = "require"
    out = Path(args.out) if args.out else None
    try:
        if out is None:
            from cosim.core import scenario

            out = Path("results") / scenario.load(args.scenario).path.stem
        output = api.run(args.scenario, plant=args.plant,
                         controller=args.controller or registry.DEFAULT, map=args.map,
                         model=args.model, options=options, problem=args.problem, out=out,
                         interface=args.interface, step=args.step, isolate=args.isolate,
                         step_timeout=args.step_timeout, seed=args.seed,
                         figure=not args.no_figure, live=live, mode=args.mode,
                         faceplate=_faceplate_options(args), hmi=hmi,
                         progress=not args.quiet and sys.stderr.isatty(),
                         on_notice=lambda text: print(f"cosim run: {text}", file=sys.stderr,
                                                      flush=True))
    except ParameterError as exc:
        raise (exc.as_option() if exc.parameter in FLAGS else CosimError(str(exc))) from None
    result = output.result
    if result.error is not None:
        if isinstance(result.error, KeyboardInterrupt):
            raise result.error
        what = "results" if result.steps == result.steps_planned else "partial results"
        raise SimulationFailed(f"{result.reason} ({what}: {result.steps} of "
                               f"{result.steps_planned} steps in {out})")
    from cosim.core import interrupts

    guard = interrupts.current()
    if guard is not None:
        guard.check()  # a signal that arrived while the results were written
    if not args.quiet:
        k = output.summary["kpis"]
        units = {o: s.get("unit") or "1"
                 for o, s in output.summary.get("signals", {}).get("outputs", {}).items()}
        iae = ", ".join(f"{o}={v:.4g} {units.get(o, '1')}·s" for o, v in k["iae"].items())
        viol = sum(v["count"] for v in k["violations"].values())
        print(f"cosim run: {result.status}: {result.steps} steps in "
              f"{result.wall_time_s:.2f} s; IAE {iae}; {viol} constraint violations; "
              f"results in {out}")
        if result.live:
            lv = result.live
            print(f"cosim run: live: {lv['fresh']} of {lv['samples']} samples fresh, "
                  f"{lv['deadline_misses']} deadline misses, {lv['watchdog_alarms']} alarms, "
                  f"{lv['reconnects']} reconnects; loop p99 "
                  f"{(lv['latency_ms']['loop']['p99'] or float('nan')):.3g} ms")
        for note in output.summary.get("controller_summary", {}).get("notes") or []:
            print(f"cosim run: note: {note}")
    return _verdict(result, out)


def _verdict(result: object, out: object) -> int:
    """The last line (stderr, also with ``--quiet``) and the exit status of a run whose
    controller did not serve a share of its steps
    (:func:`cosim.core.run_result.shortfall_verdict`: 1 beyond
    :data:`~cosim.core.run_result.FAILING_SHARE`), of a live run that did not control the
    plant (:class:`cosim.live.clock.WallClock`: 1), and of a live run with a watchdog alarm
    (which its last line says), else 0."""
    from cosim.core.errors import EXIT_FAILED, EXIT_OK
    from cosim.core.run_result import FAILING_SHARE, shortfall_verdict

    live = getattr(result, "live", None) or {}
    verdict = shortfall_verdict(result.controller_summary)  # type: ignore[attr-defined]
    if live.get("failing"):
        verdict = (1.0, result.reason)  # type: ignore[attr-defined]
    elif verdict is not None and live.get("alarms"):
        verdict = (verdict[0], f"{verdict[1]}; {live['alarms']}")
    sys.stdout.flush()   # the last line, after the run's own
    if result.status != "degraded" or verdict is None:  # type: ignore[attr-defined]
        if live.get("alarms"):
            print(f"cosim run: live: {live['alarms']}; results in {out}", file=sys.stderr,
                  flush=True)
        return EXIT_OK
    failing = verdict[0] > FAILING_SHARE
    end = ("; exit status 1" if live.get("failing") else
           "; more than half the steps: exit status 1" if failing else "")
    print(f"cosim run: degraded: {verdict[1]}{end}; results in {out}", file=sys.stderr,
          flush=True)
    return EXIT_FAILED if failing else EXIT_OK


def _faceplate_options(args: argparse.Namespace) -> object:
    """The faceplate's options (``--faceplate``: its users read, their passwords from the
    environment), or ``None``; with the run's ``--security`` options (the same as the
    plant's connection; ``None`` when not given)."""
    from cosim.core.errors import CosimError

    if args.faceplate is None:
        if args.faceplate_users is not None:
            raise CosimError("--faceplate-users: only with --faceplate URL")
        return None
    from cosim.live import faceplate, security

    sec = security.from_args(args, "server") if args.security is not None else None
    return faceplate.FaceplateOptions.of(args.faceplate, args.faceplate_users, sec)


def _live_options(args: argparse.Namespace) -> object:
    """The live options of ``--plant opc.tcp://...`` (the password read here), or ``None``
    for an FMU plant, which takes none of them."""
    from cosim.core.errors import CosimError

    given = [flag for flag, value in (("--tags", args.tags), ("--speed", args.speed),
                                      ("--watchdog", args.watchdog),
                                      ("--heartbeat", args.heartbeat),
                                      ("--min-controlled", args.min_controlled),
                                      ("--security", args.security),
                                      ("--certificate", args.certificate),
                                      ("--private-key", args.private_key),
                                      ("--trust", args.trust), ("--user", args.user))
             if value not in (None, [])]
    from cosim.core.plants import kind_of

    if not kind_of(args.plant).live:
        if given:
            raise CosimError(f"{given[0]}: only for a live plant (--plant opc.tcp://HOST:PORT)")
        return None
    from cosim.live import security
    from cosim.live.runner import LiveOptions

    sec = security.from_args(args, "client")
    return LiveOptions(tags=args.tags, speed=args.speed if args.speed is not None else 1.0,
                       watchdog=args.watchdog, security=sec, heartbeat=args.heartbeat,
                       **({"min_controlled": args.min_controlled}
                          if args.min_controlled is not None else {}))
