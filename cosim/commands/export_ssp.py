"""``cosim export-ssp``: plant FMU and controller FMU connected by name in one SSP file."""

from __future__ import annotations

import argparse
from typing import Any

from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

HELP = "write an SSP file of a plant FMU and a controller FMU connected by name"

DESCRIPTION = """\
Write an SSP 1.0 archive (SystemStructure.ssd and both FMUs under resources/) of a plant FMU
and a controller FMU (cosim export-fmu): each signal is the plant variable the controller
records for it (its problem's variable = "..."; else the signal's own name), the controller's
measured outputs read the plant's outputs and the plant's inputs read the controller's, with
the conversion between their units where they differ; the set-points ref.<output> are
constants of a parameter set (--setpoint NAME=VALUE, default: the middle of each output's
box), so are the measured disturbances dist.<name> (default: the box's middle), whose plant
variable gets the same value in its own unit (one disturbance for both), so are the controller's
tunable parameters given a value (--parameter NAME=VALUE: its weights R.<input>,
du_weight.<input>, offset_weight.<output>, offset_filter; the others keep the design's), and
the default experiment's fixed step is the controller's sample time. libcosim and other SSP
runners run it as it is (docs: guide/controller-fmu.md). Nothing that cannot run is written:
every value must be finite and inside its variable's declared range and the stop time at least
one step, and both FMUs are instantiated with these values and stepped once, each in a worker
process, before the file is written (exit 2 and one line naming what they refused)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export-ssp`` sub-command."""
    p = subparsers.add_parser("export-ssp", help=HELP, description=DESCRIPTION,
                              epilog=exit_codes_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plant", metavar="PLANT.fmu", default=None,
                   help="plant FMU (default: the project's four-tank, FMI 2.0)")
    p.add_argument("--controller", metavar="CONTROLLER.fmu", required=True,
                   help="controller FMU (cosim export-fmu)")
    p.add_argument("--setpoint", metavar="NAME=VALUE", action="append", default=[],
                   help="a set-point, e.g. ref.h1=1.3 (repeatable; default: the middle of the "
                        "output's box)")
    p.add_argument("--parameter", metavar="NAME=VALUE", action="append", default=[],
                   help="a value of the controller's tunable parameters, e.g. R.qa=0.05 "
                        "(repeatable; default: the design's)")
    p.add_argument("--stop", type=float, default=None, metavar="SECONDS",
                   help="the default experiment's stop time (default: 100 samples)")
    p.add_argument("--out", metavar="FILE.ssp", default="ClosedLoop.ssp",
                   help="the SSP file to write (default: ClosedLoop.ssp)")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def _setpoints(items: list[str], md: Any) -> dict[str, float]:
    """``--setpoint`` values over the ``ref.*`` (and measured disturbances' ``dist.*``) start
    values of the controller's model description ``md``."""
    values = {v.name: float(v.start) for v in md.modelVariables
              if v.causality == "input" and v.name.startswith(("ref.", "dist."))
              and v.start is not None}
    return {**values, **_values(items, "--setpoint")}


def _values(items: list[str], option: str) -> dict[str, float]:
    """``NAME=VALUE`` items of ``option`` as numbers by name."""
    from cosim.core.errors import CosimError

    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            sep = ""
        if not sep:
            raise CosimError(f"{option} {item}: expected NAME=VALUE with a number") from None
    return values


def run(args: argparse.Namespace) -> int:
    """Write the SSP file; print what it connects unless ``--quiet``."""
    from pathlib import Path

    from cosim.core.errors import CosimError
    from cosim.core.fmu_archive import read_model_description
    from cosim.core.plants import plant_path
    from cosim.core.ssp import wiring, write_ssp

    plant = plant_path(args.plant)
    if not Path(args.controller).is_file():
        raise CosimError(f"{args.controller}: controller FMU not found")
    md = read_model_description(args.controller)
    setpoints = _setpoints(args.setpoint, md)
    step = md.defaultExperiment
    stop = args.stop if args.stop is not None else 100 * float(getattr(step, "stepSize", 1.0)
                                                                or 1.0)
    parameters = _values(args.parameter, "--parameter")
    out = write_ssp(plant, args.controller, args.out, setpoints, stop, parameters=parameters)
    if not args.quiet:
        w = wiring(plant, Path(args.controller))
        tuned = f"; parameters {_listed(parameters)}" if parameters else ""
        shared = "".join(f"; {name} = plant.{var}" for name, (var, _) in w.disturbances.items())
        print(f"{out}: {plant.name} and {Path(args.controller).name} connected ("
              + ", ".join(f"{a} -> {b}" for a, b, _ in w.links) + "); set-points "
              + _listed(setpoints) + shared + tuned)
    return 0


def _listed(values: dict[str, float]) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in sorted(values.items()))
