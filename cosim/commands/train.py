"""``cosim train``: identify a δISS GRU from data and write the model file."""

from __future__ import annotations

import argparse
import importlib.resources
from pathlib import Path
from typing import Any

from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "MAX_EPOCHS", "MAX_STATES", "PROBLEM_OPTIONS", "SHIPPED_MODEL",
           "register", "run"]

#: The shipped model (package data of ``controllers``, ``controllers.model.DEFAULT_MODEL``):
#: never written unless named explicitly with --out.
SHIPPED_MODEL = Path(str(importlib.resources.files("controllers"))) / "models" / "fourtank_gru.json"
#: Largest --epochs accepted (the paper's recipe runs 2,000).
MAX_EPOCHS = 100_000
#: Largest --n accepted (the paper's GRU has 20 states; the MPC solves grow with n²).
MAX_STATES = 1000
#: Default epochs of the paper's recipe (the simulation method's follow the record:
#: :func:`controllers.identification.simulation.default_epochs`).
EPOCHS = {"truncated": 2000}
#: Default learning rates (first, last) of each method.
LEARNING_RATES = {"simulation": (0.03, 0.003), "truncated": (0.02, 0.0005)}
#: The options a problem file's ``[train]`` table may set (the plant's own modelling choices,
#: :attr:`controllers.problem.ControlProblem.train`), by the type of their value; the command
#: line overrides them (their flags default to absent: the table's value, else
#: :func:`_option_defaults`).
PROBLEM_OPTIONS: dict[str, type] = {"epochs": int, "n": int, "sizes": list, "seeds": int,
                                    "sigma_z_max": float, "rho_max": float,
                                    "nu_margin": float}
#: Options of ``--method truncated`` only.
TRUNCATED_ONLY = ("seq_len", "stride", "batch", "washout", "constraint", "penalty_weight",
                  "uo_weight")

HELP = "identify a δISS GRU (paper's eq. 3) from generated or logged data"

DESCRIPTION = """\
Identify the GRU of the paper (eq:gru, the inputs and outputs of the control problem) with
torch, keeping the paper's stability condition nu < 1 (Theorem 1) at every step, and write the
model file (JSON) with its training record, plus a figure of the model's free run over every
row of the data beside it.

The data: one or more CSV files (DATA.csv ...), from 'cosim generate-data' (its JSON sidecar
names the problem) or logged on the plant, with --problem: a 'time' column [s] stepping by
the problem's Ts, one column per input and output named as in the problem, optionally
'split' (train/val/test per row) and 'experiment' (a label per row). Each file and each
experiment is its own time series: never joined to another. A gap in time or a missing sample
(an empty cell, nan, NA) ends an experiment there and the rows after it start the next one;
a non-uniform step or time going backwards is an error (exit 2). Without a 'split' column
(or with --split) each experiment is split in time order: the first TRAIN fraction trains,
the next VAL validates, the rest tests (default 0.75,0.125). Files given with --val or --test
are wholly validation or test data (a separate experiment of the plant); the DATA files then
train whole unless they have a 'split' column.

--method simulation (default): the model is fitted on its free-run simulation error over
windows of the training rows (a training stretch whole up to 2,000 rows, else equal windows
of about 1,000 rows), each window starting from an initial state fitted with the weights,
never from x = 0: Adam (an epoch is six steps), then L-BFGS on all the windows (--polish).
The certified contraction rho_s (lem:Vs) is kept below a cap read from the ARX baseline's
slowest pole (a model time constant at most twice the plant's); the same candidates are also
fitted without it, and the capped model is kept unless the other is 20% better (--rho-max
sets a cap of its own). Sizes (--sizes, default 4,8,16) grow per seed (--seeds, default 2)
while a larger one lowers the validation RMS by 5%; the seeds' lanes run in parallel worker
processes (--workers) and the candidate that simulates the validation rows best is kept (each
experiment from the state estimated from its first --x0-samples samples). An output that
sits at its largest or smallest value for many samples is a sensor limit: a prediction beyond
it is no error, and simulations are read through it. --method truncated: the paper's recipe
(truncated subsequences from x = 0 with a washout, the epoch with the best validation FIT).

At the end, per split and per experiment: the free-run RMS in the outputs' units and the FIT,
next to an ARX model fitted on the same training rows (orders chosen on validation); a model
worse than that linear baseline on validation says so. The model file records it all.

The problem file's [train] table may set --epochs, --n, --sizes, --seeds, --sigma-z-max,
--rho-max and --nu-margin for its plant (sigma_z_max = 0.9); the command line overrides it.

The model file goes to --out, by default models/<DATA stem>_gru.json in the CURRENT folder
(data/fourtank.csv -> models/fourtank_gru.json). The shipped model
controllers/models/fourtank_gru.json is replaced only when --out names it explicitly. The
model file, the figure and the --history CSV are each written atomically (temporary file,
then rename): a failed write leaves the previous file byte-identical (exit 1).

Normalisation: (value - offset) / scale per signal, from the problem (default: middle and
half-width of its box, so an input's box is |u| <= 1).

examples:
  cosim train data/fourtank.csv                  # models/fourtank_gru.json + _fit.png
  cosim train log.csv --problem plant.toml       # a log: split 75/12.5/12.5 % in time order
  cosim train est.csv --val val.csv --problem plant.toml   # a separate validation run
  cosim train log.csv --problem plant.toml --n 8 --seeds 1 --epochs 150
  cosim train data/fourtank.csv --method truncated --epochs 300"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``train`` sub-command."""
    from controllers.identification.initial_state import DEFAULT_SAMPLES
    from controllers.identification.search import DEFAULT_SEEDS, DEFAULT_SIZES
    from controllers.identification.training import TrainOptions

    d = TrainOptions()
    parser = subparsers.add_parser("train", help=HELP, description=DESCRIPTION,
                                   epilog=exit_codes_help(),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("data", metavar="DATA.csv", nargs="+",
                        help="data set(s) from 'cosim generate-data', or CSVs logged on the "
                             "plant")
    parser.add_argument("--val", action="append", default=[], metavar="CSV",
                        help="a file of validation data (every row); repeat for several")
    parser.add_argument("--test", action="append", default=[], metavar="CSV",
                        help="a file of test data (every row); repeat for several")
    parser.add_argument("--problem", default=None, metavar="PROBLEM.toml",
                        help="the control problem (default: the one the data set's sidecar "
                             "records, else the four-tank's); copied into the model file")
    parser.add_argument("--split", default=None, metavar="TRAIN,VAL",
                        help="split each experiment in time order by these fractions (the "
                             "test part is the rest), even when the file has a 'split' "
                             "column (default: the 'split' column, else 0.75,0.125)")
    parser.add_argument("--out", default=None, metavar="MODEL.json",
                        help="model file to write (default: models/<DATA stem>_gru.json in "
                             "the current folder; never the shipped model unless named)")
    parser.add_argument("--figure", default=None, metavar="PNG",
                        help="figure of the free runs over the data (default: <out>_fit.png)")
    parser.add_argument("--init", default=None, metavar="MODEL.json",
                        help="start from this model file's weights (fine-tuning; its size)")
    parser.add_argument("--method", choices=("simulation", "truncated"), default="simulation",
                        help="simulation error with fitted initial states over candidates "
                             "(default), or the paper's truncated subsequences")
    parser.add_argument("--seed", type=int, default=d.seed,
                        help=f"random seed, the first of --seeds ({d.seed})")
    parser.add_argument("--epochs", type=int, default=argparse.SUPPRESS,
                        help=f"maximum epochs, at most {MAX_EPOCHS} (simulation: Adam's "
                             "steps simulate 1,000,000 rows, in 150..3000 epochs; truncated "
                             f"{EPOCHS['truncated']})")
    parser.add_argument("--n", type=int, default=argparse.SUPPRESS,
                        help=f"GRU states, at most {MAX_STATES}: one size (default: --sizes; "
                             f"{d.n} with --method truncated)")
    parser.add_argument("--sizes", default=argparse.SUPPRESS, metavar="N,N,...",
                        help="the GRU sizes tried (default "
                             f"{','.join(map(str, DEFAULT_SIZES))})")
    parser.add_argument("--seeds", type=int, default=argparse.SUPPRESS,
                        help=f"seeds tried per size (default {DEFAULT_SEEDS})")
    parser.add_argument("--workers", type=int, default=0,
                        help="worker processes fitting the candidates (default: one per CPU)")
    parser.add_argument("--x0-samples", type=int, default=DEFAULT_SAMPLES, dest="x0_samples",
                        help="samples of each experiment that estimate its initial state "
                             f"({DEFAULT_SAMPLES})")
    parser.add_argument("--window", type=int, default=0,
                        help="training window length (default: a stretch whole up to 2,000 "
                             "rows, else 1,000-row windows)")
    _training_arguments(parser)
    _contraction_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.set_defaults(func=run)


def _training_arguments(parser: argparse.ArgumentParser) -> None:
    """The optimiser's and the model's options (sequences, learning rate, the δISS
    constraint, the weights' start, early stopping)."""
    from controllers.identification.training import TrainOptions

    d = TrainOptions()
    parser.add_argument("--seq-len", type=int, default=None,
                        help=f"truncated: subsequence length (default: follows the record, "
                        f"{d.seq_len} from 5,000 training rows on)")
    parser.add_argument("--stride", type=int, default=None,
                        help="truncated: offset between subsequence starts (default: --seq-len)")
    parser.add_argument("--batch", type=int, default=None,
                        help="truncated: subsequences per step, 0 = all (default: a sixth of "
                        f"them, {d.batch} for the paper's 30)")
    parser.add_argument("--washout", type=int, default=None,
                        help="truncated: initial steps of each subsequence left out of the loss "
                        f"(default: --seq-len / 10, {d.washout} for {d.seq_len})")
    parser.add_argument("--lr", type=float, default=None,
                        help="Adam learning rate (simulation "
                             f"{LEARNING_RATES['simulation'][0]}, truncated "
                             f"{LEARNING_RATES['truncated'][0]})")
    parser.add_argument("--lr-final", type=float, default=None,
                        help="learning rate reached at the end (simulation "
                             f"{LEARNING_RATES['simulation'][1]}, truncated "
                             f"{LEARNING_RATES['truncated'][1]})")
    parser.add_argument("--nu-margin", type=float, default=argparse.SUPPRESS,
                        help=f"enforce nu <= 1 - margin ({d.nu_margin})")
    parser.add_argument("--constraint", choices=("project", "penalty"), default=None,
                        help="truncated: how nu < 1 is enforced (default project)")
    parser.add_argument("--penalty-weight", type=float, default=None,
                        help="truncated: weight of relu(nu - (1 - margin)) in the loss "
                        "(default: 10 with --constraint penalty, else 0)")
    parser.add_argument("--uo-weight", type=float, default=None,
                        help="truncated: weight of the penalty on ||U_o||_inf above --uo-max "
                        f"({d.uo_weight})")
    parser.add_argument("--uo-max", type=float, default=d.uo_max,
                        help=f"||U_o||_inf allowed without penalty ({d.uo_max})")
    parser.add_argument("--bz-init", type=float, default=d.bz_init,
                        help=f"initial update-gate bias ({d.bz_init})")
    parser.add_argument("--train-uz", action="store_true",
                        help="also train U_z (default: U_z = 0, the nu budget goes to U_h)")
    parser.add_argument("--sigma-z-max", type=float, default=argparse.SUPPRESS,
                        help="also keep sigma_z_bar <= this (0 = no cap; it sets the "
                             "contraction rates rho_s, rho_o)")
    parser.add_argument("--history", default=None, metavar="CSV",
                        help="write the training history to this CSV (truncated: per epoch, "
                             "as training goes; simulation: each candidate's validation RMS "
                             "per evaluation, when training ends)")
    parser.add_argument("--patience", type=int, default=d.patience,
                        help="stop after this many epochs without a better validation score "
                        "(0 = off)")


def _contraction_arguments(parser: argparse.ArgumentParser) -> None:
    """The certified contraction's cap and the L-BFGS stretch after Adam (simulation)."""
    parser.add_argument("--rho-max", type=float, default=argparse.SUPPRESS,
                        help="keep the certified contraction rho_s = sigma_z_bar + (1 - "
                             "sigma_z_bar) nu <= this (default, simulation: from the ARX "
                             "baseline's slowest pole, a time constant at most twice the "
                             "plant's, kept unless the uncapped fit is 20%% better; 0 = no "
                             "cap)")
    parser.add_argument("--polish", type=int, default=None,
                        help="simulation: L-BFGS iterations after Adam (default "
                             "9,000,000 / training rows, in 500..2000, in proportion when "
                             "--epochs is below its default; 0 = none)")


def _option_defaults() -> dict[str, Any]:
    """The defaults of :data:`PROBLEM_OPTIONS` (``None``: chosen later, from the record)."""
    from controllers.identification.training import TrainOptions

    d = TrainOptions()
    return {"epochs": None, "n": None, "sizes": None, "seeds": None,
            "sigma_z_max": d.sigma_z_max, "rho_max": None, "nu_margin": d.nu_margin}


def _problem_options(args: argparse.Namespace, problem: Any) -> None:
    """Fill :data:`PROBLEM_OPTIONS` not given on the command line from the problem's
    ``[train]`` table, else their defaults, and check every option (a bad value of the
    table: one line naming the problem file and line)."""
    from controllers.problem_file import locate_key
    from cosim.core.errors import CosimError

    table = dict(getattr(problem, "train", None) or {})
    unknown = sorted(set(table) - set(PROBLEM_OPTIONS))
    if unknown:
        raise CosimError(f"{locate_key(problem, 'train', unknown[0])}: [train] has no option "
                         f"{unknown[0]!r} (options: {', '.join(PROBLEM_OPTIONS)})")
    given = {key for key in PROBLEM_OPTIONS if hasattr(args, key)}
    if given & {"n", "sizes"}:   # the command line's sizes replace the table's
        table = {k: v for k, v in table.items() if k not in ("n", "sizes")}
    from_table = []
    for key, default in _option_defaults().items():
        if key in given:
            continue
        if key in table:
            setattr(args, key, _table_value(key, table[key], locate_key(problem, "train",
                                                                         key)))
            from_table.append(key)
        else:
            setattr(args, key, default)
    try:
        _check_options(args)
    except CosimError as exc:
        flag = str(exc).split(" ", 1)[0]
        key = flag.removeprefix("--").replace("-", "_")
        if key in from_table:
            raise CosimError(f"{locate_key(problem, 'train', key)}: [train] {key}: "
                             f"{str(exc).removeprefix(flag + ' ')}") from None
        raise


def _table_value(key: str, value: Any, where: str) -> Any:
    """``value`` of ``[train]``'s ``key`` as the command line would give it."""
    from cosim.core.errors import CosimError

    kind = PROBLEM_OPTIONS[key]
    if kind is list:   # --sizes 4,8: a list of sizes (or the same text)
        ok = isinstance(value, str) or (isinstance(value, list) and value and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value))
        if not ok:
            raise CosimError(f"{where}: [train] {key} must be a list of GRU sizes, got "
                             f"{value!r}")
        return value if isinstance(value, str) else ",".join(map(str, value))
    if isinstance(value, bool) or not isinstance(value, int | float) or (
            kind is int and not isinstance(value, int)):
        what = "an integer" if kind is int else "a number"
        raise CosimError(f"{where}: [train] {key} must be {what}, got {value!r}")
    return kind(value)


def _problem(args: argparse.Namespace) -> tuple[Any, bool]:
    """The control problem: ``--problem``, else the first data file's sidecar's, else the
    default; and whether it was given (by the option or the sidecar) rather than the
    default."""
    from controllers.errors import ControllersError
    from controllers.problem_file import problem_from_dict
    from cosim.adapters.problems import load_problem
    from cosim.core.errors import CosimError

    if args.problem is not None:
        return load_problem(args.problem), True
    side = Path(args.data[0]).with_suffix(".json")
    doc = _sidecar(side) or {}
    recorded = doc.get("problem") if isinstance(doc, dict) else None
    if recorded is None:
        return load_problem(None), False
    try:
        return problem_from_dict(recorded, f"{side}"), True
    except ControllersError as exc:
        raise CosimError(str(exc)) from None


def _command(argv: list[str]) -> str:
    """The command line that trained the model, without output-only options."""
    kept, skip = [], False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg in ("--out", "--figure", "--history"):
            skip = True
            continue
        if arg.split("=")[0] in ("--out", "--figure", "--history") or arg == "--quiet":
            continue
        kept.append(arg)
    return " ".join(["cosim train", *kept])


def _sidecar(path: Path) -> dict | None:
    """The data set's JSON sidecar, or None when it is missing or unreadable."""
    import json

    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None


def _out_path(args: argparse.Namespace) -> Path:
    """--out, or models/<first data stem>_gru.json; never the shipped model unless named."""
    from cosim.core.errors import CosimError

    if args.out is not None:
        return Path(args.out)
    out = Path("models") / f"{Path(args.data[0]).stem}_gru.json"
    if out.resolve() == SHIPPED_MODEL.resolve():
        raise CosimError(f"{out}: the default --out is the shipped model here; give "
                         f"--out {out} explicitly to replace it, or another --out")
    return out


def _check_options(args: argparse.Namespace) -> None:
    """Fill the method's defaults; reject option values the training cannot use (one-line
    CosimError naming the option)."""
    import math

    from cosim.core.errors import CosimError

    if args.method == "simulation":
        given = [o for o in TRUNCATED_ONLY if getattr(args, o) is not None]
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise CosimError(f"{flag} belongs to --method truncated (the default simulation "
                             "method fits whole windows from fitted initial states)")
    if args.epochs is None and args.method == "truncated":
        args.epochs = EPOCHS["truncated"]     # the simulation method's follow the record
    lr, lr_final = LEARNING_RATES[args.method]
    args.lr = lr if args.lr is None else args.lr
    args.lr_final = lr_final if args.lr_final is None else args.lr_final
    args.constraint = args.constraint or "project"
    args.uo_weight = 0.0 if args.uo_weight is None else args.uo_weight
    ints = {"--epochs": (args.epochs, 1), "--n": (args.n, 1), "--seq-len": (args.seq_len, 1),
            "--batch": (args.batch, 0), "--washout": (args.washout, 0),
            "--patience": (args.patience, 0), "--seed": (args.seed, 0),
            "--stride": (args.stride, 1), "--seeds": (args.seeds, 1),
            "--workers": (args.workers, 0), "--x0-samples": (args.x0_samples, 1),
            "--window": (args.window, 0), "--polish": (args.polish, 0)}
    for option, (value, low) in ints.items():
        if value is not None and value < low:
            raise CosimError(f"{option} must be an integer >= {low}, got {value}")
    highs = {"--epochs": (args.epochs, MAX_EPOCHS), "--n": (args.n, MAX_STATES),
             "--seed": (args.seed, 2**63 - 1), "--seeds": (args.seeds, 100)}
    for option, (value, high) in highs.items():
        if value is not None and value > high:
            raise CosimError(f"{option} must be an integer <= {high}, got {value}")
    for option, value in {"--lr": args.lr, "--lr-final": args.lr_final}.items():
        if not (math.isfinite(value) and value > 0):
            raise CosimError(f"{option} must be a positive number, got {value}")
    non_negative = {"--uo-weight": args.uo_weight, "--uo-max": args.uo_max,
                    "--penalty-weight": args.penalty_weight}
    for option, value in non_negative.items():
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise CosimError(f"{option} must be a non-negative number, got {value}")
    if not (math.isfinite(args.bz_init)):
        raise CosimError(f"--bz-init must be a finite number, got {args.bz_init}")
    if not 0 <= args.sigma_z_max < 1:
        raise CosimError(f"--sigma-z-max must be in [0, 1), got {args.sigma_z_max}")
    if args.rho_max is not None and not (args.rho_max == 0 or 0.5 < args.rho_max < 1):
        raise CosimError(f"--rho-max must be 0 (no cap) or in (0.5, 1), got {args.rho_max}")
    if not 0 < args.nu_margin < 1:
        raise CosimError(f"--nu-margin must be in (0, 1), got {args.nu_margin}")
    args.size_list = _sizes(args)


def _sizes(args: argparse.Namespace) -> list[int]:
    """The GRU sizes to try: ``--n`` alone, else ``--sizes``, else the default."""
    from controllers.identification.search import DEFAULT_SIZES
    from cosim.core.errors import CosimError

    if args.n is not None:
        if args.sizes is not None:
            raise CosimError("give --n (one size) or --sizes (several), not both")
        return [args.n]
    if args.sizes is None:
        return list(DEFAULT_SIZES)
    try:
        sizes = [int(v) for v in args.sizes.split(",")]
    except ValueError:
        sizes = []
    if not sizes or any(not 1 <= v <= MAX_STATES for v in sizes):
        raise CosimError(f"--sizes must be integers in 1..{MAX_STATES} separated by commas, "
                         f"got {args.sizes!r}")
    return sizes


def _read(args: argparse.Namespace, problem: Any, given: bool) -> Any:
    """The data of every file, one record (:func:`cosim.core.logdata.read_logs`)."""
    from cosim.core import logdata

    fractions = logdata.parse_fractions(args.split) if args.split is not None else None
    hint = "" if given else "; a logged CSV needs its problem: --problem PROBLEM.toml"
    separate = bool(args.val or args.test) and fractions is None
    files = [(p, "train" if separate and not _has_split_column(p) else None)
             for p in args.data]
    files += [(p, "val") for p in args.val] + [(p, "test") for p in args.test]
    return logdata.read_logs(files, problem.model_input_names, problem.output_names, problem.Ts,
                             problem.name, fractions, missing_hint=hint)


def _has_split_column(path: str) -> bool:
    """Whether the file's header names a ``split`` column (a file that cannot be read has
    none: :func:`cosim.core.logdata.read_log` then reports its fault)."""
    from cosim.core import csvio, logdata
    from cosim.core.errors import CosimError

    try:
        with csvio.CsvReader(Path(path), logdata.LOG_WORDING, encoding="utf-8-sig") as f:
            return logdata.SPLIT_COLUMN in [h.strip() for h in f.header()]
    except CosimError:
        return False


def run(args: argparse.Namespace) -> int:
    """Read the data, train, score against the baseline, write the model file and figure."""
    import sys
    import time

    import numpy as np

    from controllers.dead_time import delayed
    from controllers.identification.record import Record
    from cosim.commands import train_methods
    from cosim.core import outpaths
    from cosim.core.errors import CosimError

    problem, given = _problem(args)
    _problem_options(args, problem)
    data = _read(args, problem, given)
    if not np.any(data.split == "train"):
        raise CosimError(f"{args.data[0]}: no rows in split 'train'")
    out = outpaths.out_file(_out_path(args), "--out")
    figure = (outpaths.figure_file(args.figure, "--figure") if args.figure
              else out.with_name(out.stem + "_fit.png"))
    if args.history:
        outpaths.out_file(args.history, "--history")
    norm = problem.normalization()
    # the model's inputs: manipulated inputs and measured disturbances, each seen its dead
    # time late (controllers.dead_time)
    record = Record(delayed((data.u - norm["u_offset"]) / norm["u_scale"], problem.delays,
                            data.experiment),
                    (data.y - norm["y_offset"]) / norm["y_scale"], data.split,
                    data.experiment)
    progress = not args.quiet and sys.stderr.isatty()
    t0 = time.perf_counter()
    method = (train_methods.simulation if args.method == "simulation"
              else train_methods.truncated)
    trained = method(args, data, record, problem, progress)
    return train_methods.finish(args, data, record, problem, trained, out, figure,
                                time.perf_counter() - t0, _command(sys.argv[2:]),
                                _sidecar(Path(args.data[0]).with_suffix(".json")))
