"""``cosim view``: a finished run's page (or a campaign's) in a web browser."""

from __future__ import annotations

import argparse
import sys

from cosim.core.errors import exit_codes_help

#: Where the page is served without ``--hmi``.
DEFAULT_ADDRESS = "127.0.0.1:8050"

DESCRIPTION = f"""\
Serve the page of a finished run (the folder cosim run --out wrote) at http://HOST:PORT/
(default {DEFAULT_ADDRESS}) until Ctrl-C or --duration: the same page as cosim run --hmi
shows while a run goes (a panel per output and input with its limits, the status strip),
with a time slider over the run's samples and the operator's requests of its operator.csv.

Given a campaign's folder (cosim campaign --out), the page lists its runs with their KPIs
(status, violations, IAE per output), each linked to its own page.

Every script and style is served by cosim itself: the page works without the internet."""

EPILOG = """\
examples:
  cosim view results/paper_steps
  cosim view results/campaigns/theorem --hmi 0.0.0.0:8050 --hmi-users users.toml

""" + exit_codes_help()


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``view`` sub-command."""
    from cosim.commands import add_hmi_arguments

    p = subparsers.add_parser("view", help="a finished run's page (or a campaign's) in a web "
                                           "browser, with a time slider",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", metavar="RESULTS_DIR",
                   help="a run's folder (cosim run --out) or a campaign's")
    add_hmi_arguments(p, "the page", DEFAULT_ADDRESS)
    p.add_argument("--duration", metavar="SECONDS", type=float, default=None,
                   help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--quiet", action="store_true", help="no start and stop lines")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim view``; returns the exit code (0 also when stopped by a signal: that
    is how it ends)."""
    from cosim.commands import hmi_options
    from cosim.core.errors import CosimError
    from cosim.hmi.serving import serve_folder

    if args.duration is not None and not args.duration > 0:
        raise CosimError(f"--duration {args.duration!r}: must be a positive number of seconds")
    options = hmi_options(args)

    def notice(text: str) -> None:
        if not args.quiet:
            print(f"cosim view: {text}", file=sys.stderr, flush=True)

    try:
        serve_folder(args.results, options, args.duration, notice)
    except KeyboardInterrupt as exc:
        from cosim.core.interrupts import signal_name

        notice(f"stopped ({signal_name(getattr(exc, 'signum', 2))})")
        return 0
    notice("stopped (duration)")
    return 0
