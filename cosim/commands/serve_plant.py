"""``cosim serve-plant``: a plant FMU served as an OPC UA server on the wall clock."""

from __future__ import annotations

import argparse
import sys

from cosim.core.errors import exit_codes_help

DESCRIPTION = """\
Serve a plant FMU as an OPC UA server (a virtual plant), stepped on the wall clock: one
sample every Ts/K seconds (--speed K). Rehearse a controller against it exactly as it will
meet the real plant: cosim run SCENARIO --plant opc.tcp://HOST:PORT.

Below Objects, a folder named for the problem holds one AnalogItem per output (read-only,
republished every sample with its source timestamp), per input (writable: applied from the
next sample, clipped to its box) and per measured disturbance (writable: a perturbation,
republished as a measurement), each with its EngineeringUnits and EURange; Parameters/ holds
the FMU's tunable parameters (writable), Simulation/ the plant's Time and Speed and the
rehearsal switches Frozen, StaleOutputs (the outputs stop being republished) and BadOutputs
(published with status BadSensorFailure). Node ids: ns=2;s=<problem>.<name>.

The FMU runs in a worker process: a crash in it, or a step hung for 60 s, stops the server
with one line (exit 1). Stops cleanly on Ctrl-C, SIGTERM or SIGHUP (exit 0), or after
--duration seconds.
"""

EPILOG = """\
examples:
  cosim serve-plant --security None
  cosim serve-plant --security None --speed 100 --frozen --record plant.csv
  cosim serve-plant heater.fmu --problem heater.toml --endpoint opc.tcp://0.0.0.0:4841 \\
      --security Basic256Sha256,SignAndEncrypt --certificate plant.der \\
      --private-key plant.pem --trust clients/ --user operator

""" + exit_codes_help()


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``serve-plant`` sub-command."""
    from cosim.live.security import add_arguments
    from cosim.live.server import DEFAULT_ENDPOINT

    p = subparsers.add_parser(
        "serve-plant", help="serve a plant FMU over OPC UA on the wall clock (a virtual "
                            "plant to rehearse on)",
        description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plant", metavar="PLANT.fmu", nargs="?", default=None,
                   help="plant FMU (default: the project's FourTank.fmu)")
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="the control problem naming the served signals (default: the "
                        "four-tank's)")
    p.add_argument("--map", metavar="MAP", default=None,
                   help="variable map TOML for a plant whose names or units differ")
    p.add_argument("--interface", choices=("cs", "me"), default="cs",
                   help="FMI interface (default cs)")
    p.add_argument("--endpoint", metavar="URL", default=DEFAULT_ENDPOINT,
                   help=f"where to listen (default {DEFAULT_ENDPOINT})")
    p.add_argument("--speed", metavar="K", type=float, default=1.0,
                   help="speed-up: one sample every Ts/K seconds (default 1: real time)")
    p.add_argument("--frozen", action="store_true",
                   help="hold the initial state until a client writes an input (a rehearsal "
                        "then starts where an in-process run starts)")
    p.add_argument("--record", metavar="CSV", default=None,
                   help="write the plant's trajectory there (one row per sample)")
    p.add_argument("--duration", metavar="SECONDS", type=float, default=None,
                   help="stop after this many seconds of the wall clock")
    p.add_argument("--quiet", action="store_true", help="no start and stop lines")
    add_arguments(p, "server")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim serve-plant``; returns the exit code."""
    from cosim.api import serve_plant
    from cosim.live import security

    sec = security.from_args(args, "server")

    def notice(text: str) -> None:
        if not args.quiet:
            print(f"cosim serve-plant: {text}", file=sys.stderr, flush=True)

    done = serve_plant(args.plant, args.problem, endpoint=args.endpoint, speed=args.speed,
                       security=sec, frozen=args.frozen, record=args.record,
                       duration=args.duration, map=args.map, interface=args.interface,
                       on_notice=notice)
    notice(f"stopped ({done['stopped_by'] or 'done'}) after {done['samples']} samples, "
           f"{done['overruns']} overruns, {done['clipped']} clipped inputs")
    return 0
