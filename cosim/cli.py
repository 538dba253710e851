"""The ``cosim`` command line: one sub-command per module in :mod:`cosim.commands`.

Exit codes: :data:`cosim.core.errors.EXIT_CODES` (docs: guide/running.md), which ``cosim --help``
prints with what a code also means for each command (the commands' ``EXIT_NOTES``):
:class:`~cosim.core.errors.SimulationFailed` exits 1, any other
:class:`~cosim.core.errors.CosimError` 2, a signal N ``128 + N``.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import signal
import sys
import warnings
from collections.abc import Sequence

from controllers.errors import ControllersError
from cosim import __version__
from cosim.core import interrupts
from cosim.core.errors import (
    EXIT_FAILED,
    EXIT_INPUT_ERROR,
    EXIT_SIGNAL_BASE,
    CosimError,
    SimulationFailed,
    exit_codes_help,
    one_line,
)

__all__ = ["COMMANDS", "build_parser", "entry", "main"]

#: Sub-command modules, in the order ``cosim --help`` lists them. Each defines
#: ``register(subparsers)`` that adds its parser and sets ``func(args) -> int``, and may define
#: ``EXIT_NOTES`` (exit code → what it also means for the command, shown by
#: :func:`~cosim.core.errors.exit_codes_help`); heavy imports (casadi, torch, fmpy) happen inside
#: ``func`` so that ``--help`` stays fast.
COMMANDS = (
    "cosim.commands.run",
    "cosim.commands.view",
    "cosim.commands.serve_plant",
    "cosim.commands.make_certificate",
    "cosim.commands.build_fmu",
    "cosim.commands.build_kernel",
    "cosim.commands.export_fmu",
    "cosim.commands.export_ssp",
    "cosim.commands.generate_data",
    "cosim.commands.train",
    "cosim.commands.certify",
    "cosim.commands.tune",
    "cosim.commands.compare",
    "cosim.commands.campaign",
)

def build_parser() -> argparse.ArgumentParser:
    """Return the top-level parser with every available sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="cosim",
        description="Robust GRU-based MPC tested by FMI co-simulation.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    notes: dict[str, dict[int, str]] = {}
    for module_name in COMMANDS:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue  # command not shipped in this build
            raise
        module.register(subparsers)
        if getattr(module, "EXIT_NOTES", None):
            notes[list(subparsers.choices)[-1]] = module.EXIT_NOTES
    parser.epilog = exit_codes_help(notes)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cosim`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)

    def one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                         lineno: int, file: object = None, line: str | None = None) -> None:
        print(f"cosim {args.command}: warning: {one_line(str(message))}", file=sys.stderr)

    warnings.showwarning = one_line_warning
    try:
        with interrupts.handling_signals():
            return int(args.func(args) or 0)
    except SimulationFailed as exc:
        print(f"cosim {args.command}: failed: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_FAILED
    except CosimError as exc:
        print(f"cosim {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except ControllersError as exc:
        # the numerical core's errors: a ValueError is bad input, a RuntimeError a failure
        if isinstance(exc, RuntimeError):
            print(f"cosim {args.command}: failed: {one_line(str(exc))}", file=sys.stderr)
            return EXIT_FAILED
        print(f"cosim {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"cosim {args.command}: interrupted ({interrupts.signal_name(signum)})",
              file=sys.stderr)
        return EXIT_SIGNAL_BASE + signum


def entry() -> None:
    """The ``cosim`` console script and ``python -m cosim.cli``: :func:`main`, then exit
    with its code.

    FMU libraries are never unloaded (:meth:`cosim.core.fmu.FmuComponent.terminate`), so their
    destructors run when the process exits, after Python's own shutdown, and they are native
    code that may crash: pythonfmu's ``finalizePythonInterpreter`` reads memory its static
    destructors have just freed (valgrind: an invalid read at ``_dl_fini``), which now and
    then ends a finished ``cosim run`` with ``corrupted double-linked list`` and exit 134.
    A command that loaded an FMU therefore runs Python's exit handlers (temporary folders,
    finalizers, log flushing) and leaves with ``os._exit``, so that its exit code is its own.
    """
    code = main()
    fmu = sys.modules.get("cosim.core.fmu")
    if fmu is None or not fmu.libraries_loaded():
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(code)


if __name__ == "__main__":
    entry()
