"""The ``cosim`` command line: one sub-command per module in :mod:`cosim.commands`.

Exit codes (also in the README):

* 0 -- success;
* 1 -- a run failed mid-way (results up to the fault are kept), or ``compare`` found a
  deviation outside the tolerance band;
* 2 -- bad input or usage (scenario, map, model file, FMU, options): nothing was run;
* 128 + N -- stopped by signal N: 130 SIGINT (Ctrl-C), 143 SIGTERM, 129 SIGHUP (results up
  to the signal are kept).
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
from collections.abc import Sequence

from cosim import __version__, interrupts
from cosim.errors import (
    EXIT_FAILED,
    EXIT_INPUT_ERROR,
    EXIT_SIGNAL_BASE,
    CosimError,
    SimulationFailed,
)

#: Sub-command modules, in the order ``cosim --help`` lists them. Each defines
#: ``register(subparsers)`` that adds its parser and sets ``func(args) -> int``; heavy imports
#: (casadi, torch, fmpy) happen inside ``func`` so that ``--help`` stays fast.
COMMANDS = (
    "cosim.commands.run",
    "cosim.commands.build_fmu",
    "cosim.commands.generate_data",
    "cosim.commands.train",
    "cosim.commands.certify",
    "cosim.commands.compare",
)

EPILOG = """exit codes:
  0    success
  1    a run failed mid-way (partial results kept), an output file could not be written,
       or compare found deviations
  2    bad input or usage; nothing was run
  130  interrupted by Ctrl-C (SIGINT); 143 by SIGTERM, 129 by SIGHUP (partial results kept)"""


def build_parser() -> argparse.ArgumentParser:
    """Return the top-level parser with every available sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="cosim",
        description="Robust GRU-based MPC tested by FMI co-simulation.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in COMMANDS:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue  # command not shipped in this build
            raise
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cosim`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with interrupts.handling_signals():
            return int(args.func(args) or 0)
    except SimulationFailed as exc:
        print(f"cosim {args.command}: failed: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except CosimError as exc:
        print(f"cosim {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"cosim {args.command}: interrupted ({interrupts.signal_name(signum)})",
              file=sys.stderr)
        return EXIT_SIGNAL_BASE + signum


if __name__ == "__main__":
    sys.exit(main())
