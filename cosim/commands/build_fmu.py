"""``cosim build-fmu``: compile and zip the four-tank plant FMUs (FMI 2.0 and 3.0)."""

from __future__ import annotations

import argparse

from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

HELP = "compile the four-tank plant FMUs (fmus/FourTank.fmu, fmus/FourTank3.fmu)"

DESCRIPTION = """\
Compile the C sources in fmus/fourtank/ (package data of the installed fmus package) with
gcc and zip two FMUs, each with the Co-Simulation and Model Exchange interfaces and its C
sources inside (source FMU):

  fmus/FourTank.fmu    FMI 2.0
  fmus/FourTank3.fmu   FMI 3.0

They are written beside their sources when that folder is writable (a source checkout:
fmus/FourTank.fmu), else into the user cache folder, ~/.cache/gru-mpc/fmus on Linux
($XDG_CACHE_HOME respected); the command prints where. An FMU is rebuilt only when its
sources, model description or compiler changed. Intermediate files go to build/ beside the
FMUs."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``build-fmu`` sub-command."""
    parser = subparsers.add_parser(
        "build-fmu",
        help=HELP,
        description=DESCRIPTION,
        epilog=exit_codes_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--force", action="store_true", help="rebuild even if the sources are unchanged"
    )
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the FMUs; print one line per FMU unless ``--quiet``."""
    from cosim.core.build import TARGETS, build_fmu, compiler, display_path

    compiler()  # fail early with a one-line error if gcc is missing
    for target in TARGETS:
        rebuilt = build_fmu(target, force=args.force)
        if not args.quiet:
            state = "built" if rebuilt else "up to date"
            print(f"{display_path(target.fmu_path)}: {state}")
    return 0
