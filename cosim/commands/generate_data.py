"""``cosim generate-data``: identification data from a plant FMU (paper, section V)."""

from __future__ import annotations

import argparse

from cosim.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

#: The plant used when --plant is not given: the project's FMU, whatever the current folder.

HELP = "excite a plant FMU with a multilevel pseudo-random signal and record the data set"

DESCRIPTION = """\
Drive the plant FMU with piecewise-constant inputs (random levels inside the saturation
box of controllers.problem.FOURTANK, log-uniform random hold times), sample every Ts = 25 s
and write a CSV (time, inputs, all plant outputs, split) plus a JSON sidecar recording how
it was made. The record is split train/validation/test in the proportions 75/12.5/12.5 %
(15,000/2,500/2,500 for the default 20,000 steps). The same seed gives the same file.

With --map, the plant may be a third-party FMU whose variables differ in name or unit
(variable maps: docs/guide/own-plant.md); every map entry is checked against the FMU before
the first step. The CSV is always in project names and SI units. The CSV and its sidecar
are written atomically: a failed write leaves the previous files unchanged (exit 1).

examples:
  cosim generate-data                              # data/fourtank.csv, seed 0
  cosim generate-data --steps 2000 --seed 3 --out data/short.csv
  cosim generate-data --plant other.fmu --map other.toml"""


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
    parser.add_argument("--hold-min", type=int, default=2,
                        help="shortest input hold time in samples (default: 2)")
    parser.add_argument("--hold-max", type=int, default=80,
                        help="longest input hold time in samples (default: 80)")
    parser.add_argument("--out", default="data/fourtank.csv", metavar="CSV",
                        help="output CSV (default: data/fourtank.csv)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Generate the data set and print a one-line summary per split."""
    import sys

    import numpy as np

    from controllers.problem import FOURTANK
    from cosim import datagen, outpaths
    from cosim.errors import CosimError
    from cosim.master import MAX_STEPS

    if args.steps < 10:
        raise CosimError(f"--steps must be at least 10, got {args.steps}")
    if args.steps > MAX_STEPS:
        raise CosimError(f"--steps must be at most {MAX_STEPS}, got {args.steps}")
    if args.seed < 0:
        raise CosimError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.hold_max > MAX_STEPS:
        raise CosimError(f"--hold-max must be at most {MAX_STEPS} samples, got {args.hold_max}")
    if not 1 <= args.hold_min <= args.hold_max:
        raise CosimError(f"--hold-min and --hold-max must satisfy 1 <= --hold-min <= "
                         f"--hold-max, got {args.hold_min} and {args.hold_max}")
    out = outpaths.out_file(args.out, "--out")
    if out.suffix.lower() == ".json":
        raise CosimError(f"{out}: --out must not end in .json: that name is the data's JSON "
                         "sidecar (use .csv)")
    from cosim.api import plant_path as find_plant

    plant_path = find_plant(args.plant)
    plant = datagen.fmu_plant(plant_path, args.map, args.interface)
    # every plant output is recorded (h1..h4 for the four tanks); inputs and the controlled
    # outputs are checked against the FMU (and the map): names, causality, units
    outputs = list(dict.fromkeys([*FOURTANK.outputs, *(s.name for s in plant.outputs)]))
    units = dict(zip(FOURTANK.inputs + FOURTANK.outputs,
                     FOURTANK.input_units + FOURTANK.output_units, strict=True))
    plant.check_signals(list(FOURTANK.inputs), outputs, units)
    progress = not args.quiet and sys.stderr.isatty()
    data = datagen.generate(plant, args.steps, args.seed, FOURTANK.input_bounds,
                            FOURTANK.inputs, outputs, FOURTANK.Ts,
                            (args.hold_min, args.hold_max), progress)
    meta = {"plant": str(plant_path), "map": args.map, "interface": args.interface,
            "seed": args.seed, "Ts": FOURTANK.Ts, "hold": [args.hold_min, args.hold_max],
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
