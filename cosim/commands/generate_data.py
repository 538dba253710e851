"""``cosim generate-data``: identification data from a plant FMU (paper, section V)."""

from __future__ import annotations

import argparse
from typing import Any

from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

#: Input hold times [samples] when neither the problem nor the command line gives them.
DEFAULT_HOLD = (2, 80)

HELP = "excite a plant FMU with a multilevel pseudo-random signal and record the data set"

DESCRIPTION = """\
Drive the plant FMU with piecewise-constant inputs (random levels inside each input's box,
or its 'levels', of the control problem; log-uniform random hold times, the input's 'hold'
or --hold-min/--hold-max), sample every Ts of the problem and write a CSV (time, inputs, all
plant outputs, split) plus a JSON sidecar recording how it was made, the problem included
(cosim train takes it from there). The default problem is the four-tank's. The record is
split train/validation/test in the proportions 75/12.5/12.5 % (15,000/2,500/2,500 for the
default 20,000 steps). The same seed gives the same file.

The plant FMU is bound to the problem before the first step: each signal is the FMU
variable of its name, or the one its 'variable' key names; units are converted where the
problem's and the FMU's differ (the FMU's UnitDefinitions, else pint), and a variable the FMU
lacks, of the wrong causality or type, or in a unit it contradicts is one line naming the
problem file and line (exit 2). With --map, a third-party FMU whose variables differ in name
or unit binds through a variable map (docs/guide/own-plant.md), which takes precedence; every
map entry is checked too. The CSV is always in the problem's names and units. The CSV and its
sidecar are written atomically: a failed write leaves the previous files unchanged (exit 1).

examples:
  cosim generate-data                              # data/fourtank.csv, seed 0
  cosim generate-data --steps 2000 --seed 3 --out data/short.csv
  cosim generate-data --plant other.fmu --map other.toml
  cosim generate-data --plant cstr.fmu --problem cstr.toml --out data/cstr.csv"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``generate-data`` sub-command."""
    parser = subparsers.add_parser("generate-data", help=HELP, description=DESCRIPTION,
                                   epilog=exit_codes_help(),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--plant", default=None, metavar="FMU",
                        help="plant FMU (default: the project's FourTank.fmu, built if missing, "
                             "see cosim build-fmu; not relative to the current folder)")
    parser.add_argument("--map", default=None, metavar="MAP",
                        help="variable map (TOML) for a third-party plant")
    parser.add_argument("--interface", choices=("cs", "me"), default="cs",
                        help="FMI interface to use (default: cs)")
    parser.add_argument("--steps", type=int, default=20000,
                        help="number of samples, 10 to 1,000,000 (default: 20000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--problem", default=None, metavar="PROBLEM.toml",
                        help="the control problem (default: the four-tank's, "
                             "fmus/fourtank/problem.toml); the plant FMU is bound to it "
                             "(variables, units) before the first step")
    parser.add_argument("--hold-min", type=int, default=None,
                        help="shortest input hold time in samples (default: each input's "
                             "'hold' in the problem, else 2)")
    parser.add_argument("--hold-max", type=int, default=None,
                        help="longest input hold time in samples (default: each input's "
                             "'hold' in the problem, else 80)")
    parser.add_argument("--out", default="data/fourtank.csv", metavar="CSV",
                        help="output CSV (default: data/fourtank.csv)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Generate the data set and print a one-line summary per split."""
    import sys

    import numpy as np

    from cosim.adapters.problems import bind_plant, load_problem
    from cosim.core import datagen, outpaths, varmap
    from cosim.core.errors import CosimError

    _check_numbers(args)
    problem = load_problem(args.problem)
    holds = _holds(args, problem)
    out = outpaths.out_file(args.out, "--out")
    if out.suffix.lower() == ".json":
        raise CosimError(f"{out}: --out must not end in .json: that name is the data's JSON "
                         "sidecar (use .csv)")
    from cosim.core.plants import plant_path as find_plant

    plant_path = find_plant(args.plant)
    user_map = varmap.load(args.map) if args.map else None
    plant = datagen.fmu_plant(plant_path, interface=args.interface,
                              varmap=bind_plant(problem, plant_path, user_map))
    # every plant output is recorded (h1..h4 for the four tanks); inputs and the controlled
    # outputs are checked against the FMU (and the map): names, causality, units
    outputs = list(dict.fromkeys([*problem.output_names, *(s.name for s in plant.outputs)]))
    plant.check_signals(list(problem.model_input_names), outputs, problem.units())
    progress = not args.quiet and sys.stderr.isatty()
    levels = [c.levels if c.levels is not None else c.bounds for c in problem.model_inputs]
    data = datagen.generate(plant, args.steps, args.seed, levels, problem.model_input_names,
                            outputs, problem.Ts, holds, progress)
    meta = {"plant": str(plant_path), "map": args.map, "interface": args.interface,
            "seed": args.seed, "Ts": problem.Ts, "hold": [list(h) for h in holds],
            "problem": problem.to_dict(),
            "command": "cosim generate-data " + " ".join(sys.argv[2:])}
    path = datagen.write_csv(data, args.out, meta)
    if not args.quiet:
        print(f"{path}: {args.steps} steps, seed {args.seed}")
        for name in datagen.SPLITS:
            _, y = data.part(name)
            ranges = ", ".join(f"{o} {lo:.2f}..{hi:.2f}" for o, lo, hi
                               in zip(outputs, np.min(y, axis=0), np.max(y, axis=0),
                                      strict=True))
            print(f"  {name:5s} {y.shape[0]:6d} rows  {ranges}")
    return 0


def _check_numbers(args: argparse.Namespace) -> None:
    """``--steps`` in [10, MAX_STEPS], ``--seed`` not negative, the hold times in samples."""
    from cosim.core.errors import CosimError
    from cosim.core.master import MAX_STEPS

    if args.steps < 10:
        raise CosimError(f"--steps must be at least 10, got {args.steps}")
    if args.steps > MAX_STEPS:
        raise CosimError(f"--steps must be at most {MAX_STEPS}, got {args.steps}")
    if args.seed < 0:
        raise CosimError(f"--seed must be a non-negative integer, got {args.seed}")
    for flag, value in (("--hold-min", args.hold_min), ("--hold-max", args.hold_max)):
        if value is not None and not 1 <= value <= MAX_STEPS:
            raise CosimError(f"{flag} must be in [1, {MAX_STEPS}] samples, got {value}")


def _holds(args: argparse.Namespace, problem: Any) -> list[tuple[int, int]]:
    """Each model input's hold times [samples]: ``--hold-min``/``--hold-max`` over its
    ``hold`` in the problem, over :data:`DEFAULT_HOLD`."""
    from cosim.core.errors import CosimError

    holds = []
    for c in problem.model_inputs:
        lo, hi = c.hold if c.hold is not None else DEFAULT_HOLD
        lo = args.hold_min if args.hold_min is not None else lo
        hi = args.hold_max if args.hold_max is not None else hi
        if not 1 <= lo <= hi:
            raise CosimError(f"{_kind(problem, c.name)} {c.name}: hold times must satisfy "
                             f"1 <= min <= max, got "
                             f"{lo} and {hi} (--hold-min, --hold-max or the problem's 'hold')")
        holds.append((lo, hi))
    return holds


def _kind(problem: Any, name: str) -> str:
    return "disturbance" if name in problem.disturbance_names else "input"
