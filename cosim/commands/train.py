"""``cosim train``: train a δISS GRU on a data set and write the model file."""

from __future__ import annotations

import argparse
import importlib.resources
from pathlib import Path
from typing import Any

from cosim.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "MAX_EPOCHS", "MAX_STATES", "SHIPPED_MODEL", "register",
           "run"]

#: The shipped model (package data of ``controllers``, ``controllers.model.DEFAULT_MODEL``):
#: never written unless named explicitly with --out.
SHIPPED_MODEL = Path(str(importlib.resources.files("controllers"))) / "models" / "fourtank_gru.json"
#: Largest --epochs accepted (the paper's recipe runs 2,000).
MAX_EPOCHS = 100_000
#: Largest --n accepted (the paper's GRU has 20 states; the MPC solves grow with n²).
MAX_STATES = 1000

HELP = "train a δISS GRU (paper's eq. 3) on generated or logged data"

DESCRIPTION = """\
Train the GRU of the paper (eq:gru, n states, the inputs and outputs of the control problem)
with torch on the training split, select the epoch with the best validation FIT, and write
the model file (JSON) with its training record, plus a figure of the test-split prediction
beside it.

The data: a data set from 'cosim generate-data' (its JSON sidecar names the problem) or a CSV
logged on the plant, with --problem: a 'time' column [s] stepping by the problem's Ts, one
column per input and output named as in the problem, optionally 'split' (train/val/test per
row) and 'experiment' (a label per row: experiments are never joined; training subsequences
stay inside one, the open-loop FIT restarts at each). Other columns are ignored. Without a
'split' column (or with --split) each experiment is split in time order: the first TRAIN
fraction trains, the next VAL validates, the rest tests (default 0.75,0.125). A gap, a
non-uniform step, time going backwards or another sample time than Ts is an error (exit 2).
The model file's training record names the file, its SHA-256, rows, experiments, split and
the columns used.

The model file goes to --out, by default models/<DATA stem>_gru.json in the CURRENT folder
(data/fourtank.csv -> models/fourtank_gru.json). The shipped model
controllers/models/fourtank_gru.json is replaced only when --out names it explicitly
(cosim train data/fourtank.csv --out controllers/models/fourtank_gru.json). The model file,
the figure and the --history CSV are each written atomically (temporary file, then rename):
a failed write leaves the previous file byte-identical (exit 1). The --history lines go to a
temporary file beside it, one per epoch, which replaces the --history file when training
ends (an interrupted or failed training leaves the previous --history file unchanged).

Subsequence length, washout and batch follow the training rows T when not given:
--seq-len min(500, max(20, T/10), longest training stretch), --washout seq-len/10, --batch
(number of subsequences)/6 rounded (six steps per epoch): 15,000 training rows give the
paper's 500, 50 and 5. The δISS condition of Theorem 1 (nu < 1) is enforced by rescaling the
recurrent weights so that nu <= 1 - margin at every step (--constraint project, default) or
by the paper's penalty (--constraint penalty). A model with nu >= 1 is never saved.

Normalisation: (value - offset) / scale per signal, from the problem (default: middle and
half-width of its box, so an input's box is |u| <= 1).

examples:
  cosim train data/fourtank.csv                  # models/fourtank_gru.json + _test.png
  cosim train data/fourtank.csv --epochs 20 --out /tmp/m.json
  cosim train log.csv --problem plant.toml --split 0.7,0.15 --epochs 300
  cosim train data/fourtank.csv --out controllers/models/fourtank_gru.json  # replace shipped
  cosim train data/fourtank.csv --init controllers/models/fourtank_gru.json --lr 1e-3"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``train`` sub-command."""
    from controllers.training import TrainOptions

    d = TrainOptions()
    parser = subparsers.add_parser("train", help=HELP, description=DESCRIPTION,
                                   epilog=exit_codes_help(),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("data", metavar="DATA.csv",
                        help="data set from 'cosim generate-data', or a CSV logged on the plant")
    parser.add_argument("--problem", default=None, metavar="PROBLEM.toml",
                        help="the control problem (default: the one the data set's sidecar "
                             "records, else the four-tank's); copied into the model file")
    parser.add_argument("--split", default=None, metavar="TRAIN,VAL",
                        help="split each experiment in time order by these fractions (the "
                             "test part is the rest), even when the file has a 'split' "
                             "column (default: the 'split' column, else 0.75,0.125)")
    parser.add_argument("--out", default=None, metavar="MODEL.json",
                        help="model file to write (default: models/<DATA stem>_gru.json in "
                        "the current folder; the shipped controllers/models/fourtank_gru.json "
                        "is written only when named here)")
    parser.add_argument("--figure", default=None, metavar="PNG",
                        help="test-split prediction figure (default: <out>_test.png)")
    parser.add_argument("--init", default=None, metavar="MODEL.json",
                        help="start from this model file's weights (fine-tuning)")
    parser.add_argument("--seed", type=int, default=d.seed, help=f"random seed ({d.seed})")
    parser.add_argument("--epochs", type=int, default=d.epochs,
                        help=f"maximum epochs, at most {MAX_EPOCHS} ({d.epochs})")
    parser.add_argument("--n", type=int, default=d.n,
                        help=f"GRU states, at most {MAX_STATES} ({d.n})")
    parser.add_argument("--seq-len", type=int, default=None,
                        help=f"training subsequence length (default: follows the record, "
                        f"{d.seq_len} from 5,000 training rows on)")
    parser.add_argument("--stride", type=int, default=None,
                        help="offset between subsequence starts (default: --seq-len)")
    parser.add_argument("--batch", type=int, default=None,
                        help="subsequences per step, 0 = all (default: a sixth of them, "
                        f"{d.batch} for the paper's 30)")
    parser.add_argument("--washout", type=int, default=None,
                        help="initial steps of each subsequence left out of the loss "
                        f"(default: --seq-len / 10, {d.washout} for {d.seq_len})")
    parser.add_argument("--lr", type=float, default=d.lr, help=f"Adam learning rate ({d.lr})")
    parser.add_argument("--lr-final", type=float, default=d.lr_final,
                        help=f"learning rate reached at the last epoch ({d.lr_final})")
    parser.add_argument("--nu-margin", type=float, default=d.nu_margin,
                        help=f"enforce nu <= 1 - margin ({d.nu_margin})")
    parser.add_argument("--constraint", choices=("project", "penalty"), default=d.constraint,
                        help=f"how nu < 1 is enforced ({d.constraint})")
    parser.add_argument("--penalty-weight", type=float, default=None,
                        help="weight of relu(nu - (1 - margin)) in the loss "
                        "(default: 10 with --constraint penalty, else 0)")
    parser.add_argument("--uo-weight", type=float, default=d.uo_weight,
                        help=f"weight of the penalty on ||U_o||_inf above --uo-max "
                        f"({d.uo_weight})")
    parser.add_argument("--uo-max", type=float, default=d.uo_max,
                        help=f"||U_o||_inf allowed without penalty ({d.uo_max})")
    parser.add_argument("--bz-init", type=float, default=d.bz_init,
                        help=f"initial update-gate bias ({d.bz_init})")
    parser.add_argument("--train-uz", action="store_true",
                        help="also train U_z (default: U_z = 0, the nu budget goes to U_h)")
    parser.add_argument("--sigma-z-max", type=float, default=d.sigma_z_max,
                        help="with --constraint project, also keep sigma_z_bar <= this "
                        "(0 = no cap; it sets the contraction rates rho_s, rho_o)")
    parser.add_argument("--history", default=None, metavar="CSV",
                        help="write per-epoch loss, validation FIT and nu to this CSV "
                        "(appended to a temporary file as training goes, which replaces CSV "
                        "when training ends)")
    parser.add_argument("--patience", type=int, default=d.patience,
                        help="stop after this many epochs without a better validation FIT "
                        "(0 = off)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.set_defaults(func=run)


def _problem(args: argparse.Namespace) -> tuple[Any, bool]:
    """The control problem: ``--problem``, else the data sidecar's, else the default; and
    whether it was given (by the option or the sidecar) rather than the default."""
    import json

    from controllers.errors import ControllersError
    from controllers.problem_file import problem_from_dict
    from cosim.errors import CosimError
    from cosim_adapters.problems import load_problem

    if args.problem is not None:
        return load_problem(args.problem), True
    side = Path(args.data).with_suffix(".json")
    try:
        doc = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        doc = {}
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
    """--out, or models/<data stem>_gru.json; never the shipped model unless named."""
    from cosim.errors import CosimError

    if args.out is not None:
        return Path(args.out)
    out = Path("models") / f"{Path(args.data).stem}_gru.json"
    if out.resolve() == SHIPPED_MODEL.resolve():
        raise CosimError(f"{out}: the default --out is the shipped model here; give "
                         f"--out {out} explicitly to replace it, or another --out")
    return out


def _check_options(args: argparse.Namespace) -> None:
    """Reject option values the training cannot use (one-line CosimError naming the option)."""
    import math

    from cosim.errors import CosimError

    ints = {"--epochs": (args.epochs, 1), "--n": (args.n, 1), "--seq-len": (args.seq_len, 1),
            "--batch": (args.batch, 0), "--washout": (args.washout, 0),
            "--patience": (args.patience, 0), "--seed": (args.seed, 0),
            "--stride": (args.stride, 1)}
    for option, (value, low) in ints.items():
        if value is not None and value < low:
            raise CosimError(f"{option} must be an integer >= {low}, got {value}")
    highs = {"--epochs": (args.epochs, MAX_EPOCHS), "--n": (args.n, MAX_STATES),
             "--seed": (args.seed, 2**63 - 1)}
    for option, (value, high) in highs.items():
        if value > high:
            raise CosimError(f"{option} must be an integer <= {high}, got {value}")
    positive = {"--lr": args.lr, "--lr-final": args.lr_final}
    for option, value in positive.items():
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


def run(args: argparse.Namespace) -> int:
    """Read the data, train, check ν < 1, write the model file and the figure."""
    import contextlib
    import sys
    import time
    from pathlib import Path

    import numpy as np

    from controllers import bounds, metrics, sequences, training
    from controllers.model import GRUModel
    from cosim import datagen, logdata, outpaths, plots
    from cosim.atomicio import output_error, replacing
    from cosim.errors import CosimError

    _check_options(args)
    if not 0 < args.nu_margin < 1:
        raise CosimError(f"--nu-margin must be in (0, 1), got {args.nu_margin}")
    fractions = logdata.parse_fractions(args.split) if args.split is not None else None
    problem, given = _problem(args)
    hint = "" if given else "; a logged CSV needs its problem: --problem PROBLEM.toml"
    data = logdata.read_log(args.data, problem.input_names, problem.output_names, problem.Ts,
                            problem.name, fractions, missing_hint=hint)
    for name in datagen.SPLITS:
        if not np.any(data.split == name):
            raise CosimError(f"{args.data}: no rows in split '{name}'")
    spans = sequences.stretches(data.split, data.experiment, "train")
    lengths = [b - a for a, b in spans]
    auto = sequences.record_defaults(lengths, args.seq_len, args.washout, args.batch,
                                     args.stride)
    if auto.subsequences == 0:
        raise CosimError(f"{args.data}: the longest training stretch has {max(lengths)} steps "
                         f"(of {sum(lengths)} training rows), fewer than --seq-len "
                         f"{auto.seq_len}")
    if not 0 <= auto.washout < auto.seq_len:
        raise CosimError(f"--washout must be in [0, --seq-len), got {auto.washout}")
    penalty = args.penalty_weight
    if penalty is None:
        penalty = 10.0 if args.constraint == "penalty" else 0.0
    opts = training.TrainOptions(
        n=args.n, seq_len=auto.seq_len, stride=args.stride, batch=auto.batch,
        epochs=args.epochs, lr=args.lr, lr_final=args.lr_final, washout=auto.washout,
        nu_margin=args.nu_margin, constraint=args.constraint, penalty_weight=penalty,
        uo_weight=args.uo_weight, uo_max=args.uo_max, bz_init=args.bz_init,
        patience=args.patience, sigma_z_max=args.sigma_z_max, train_uz=args.train_uz,
        seed=args.seed)
    out = outpaths.out_file(_out_path(args), "--out")
    figure = (outpaths.figure_file(args.figure, "--figure") if args.figure
              else out.with_name(out.stem + "_test.png"))
    if args.history:
        outpaths.out_file(args.history, "--history")

    norm = problem.normalization()
    u_all = (data.u - norm["u_offset"]) / norm["u_scale"]
    y_all = (data.y - norm["y_offset"]) / norm["y_scale"]
    train_mask = data.split == "train"
    init = None
    if args.init:
        start = GRUModel.load(args.init)
        if start.params["W_z"].shape != (opts.n, problem.m):
            raise CosimError(f"{args.init}: model has n={start.n}, but --n is {opts.n}")
        init = start.params

    names = list(problem.output_names)
    progress = not args.quiet and sys.stderr.isatty()
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        callback = None
        if args.history:
            history = Path(args.history)
            # lines go to a temporary file beside --history, renamed onto it at the end
            tmp = stack.enter_context(replacing(history))
            fh = stack.enter_context(open(tmp, "w", encoding="utf-8", newline=""))

            def log(line: str) -> None:
                try:
                    fh.write(line)
                    fh.flush()
                except OSError as exc:
                    raise output_error(history, exc) from None

            log("epoch,time_s,loss,nu," + "".join(f"fit_val_{n}," for n in names)
                + "U_o_inf_norm\n")

            def callback(epoch: int, rec: dict, _weights: dict) -> None:
                log(f"{epoch},{rec['time']:.2f},{rec['loss']:.6e},{rec['nu']:.6f},"
                    + "".join(f"{f:.4f}," for f in rec["fit_val"])
                    + f"{rec['uo_norm']:.4f}\n")

        result = training.train(u_all[train_mask], y_all[train_mask], u_all, y_all,
                                data.split, opts, progress=progress, init=init,
                                callback=callback, experiment=data.experiment)
    scores = metrics.split_scores(result.params, u_all, y_all, data.split, data.experiment)
    sz, sr, ph = bounds.gate_bounds(result.params)
    meta_path = Path(args.data).with_suffix(".json")
    record = {
        "command": _command(sys.argv[2:]),
        "data": str(args.data),
        "data_meta": _sidecar(meta_path),
        "data_file": data.provenance,
        "seed": opts.seed,
        "init": args.init,
        "epochs_run": result.epochs_run,
        "best_epoch": result.best_epoch,
        "options": result.options,
        "subsequences": {"count": auto.subsequences, "training_stretches": len(spans),
                         "from_record": [o for o, v in (("seq_len", args.seq_len),
                                                        ("washout", args.washout),
                                                        ("batch", args.batch)) if v is None]},
        "fit": {s: _named(names, scores[s]["fit"]) for s in scores},
        "max_abs_err": {s: scores[s]["max_abs_err"] for s in scores},
        "fit_protocol": "open-loop simulation of each experiment from x = 0 (the whole record "
                        "when it is one), inputs only; FIT per split on its rows of every "
                        "experiment (normalised units)",
        "nu": result.nu,
        "sigma_z_bar": sz, "sigma_r_bar": sr, "phi_h_bar": ph,
        "U_o_inf_norm": bounds.inf_norm(result.params["U_o"]),
        "normalization_note": "(value - offset) / scale, offset and scale per signal from "
                              "the problem (default: middle and half-width of its box)",
        "wall_time_s": round(time.perf_counter() - t0, 1),
        "torch_version": __import__("torch").__version__,
    }
    if data.n_experiments > 1:
        per = metrics.experiment_scores(result.params, u_all, y_all, data.split,
                                        data.experiment)
        record["fit_per_experiment"] = [
            {"experiment": label, "fit": {s: _named(names, sc[s]["fit"]) for s in sc}}
            for label, sc in zip(data.experiment_names, per, strict=True)]
    w_y_bar = scores["test"]["max_abs_err"]
    model = training.build_model(result.params, problem, record, w_y_bar=w_y_bar)
    try:
        model.save(out)  # atomic: a failed write leaves the previous file unchanged
    except OSError as exc:
        raise output_error(out, exc) from None

    test = data.split == "test"
    xi = metrics.open_loop_experiments(result.params, u_all, data.experiment)
    # several experiments: their test rows one after the other, on one time axis
    t_test = (data.time[test] if data.n_experiments == 1
              else np.arange(np.count_nonzero(test)) * problem.Ts)
    with replacing(figure) as tmp_figure:
        plots.prediction_figure(
            t_test, model.denormalize_y(y_all[test]), model.denormalize_y(xi[test]),
            names, list(problem.output_units), scores["test"]["fit"], str(tmp_figure),
            f"GRU n={opts.n}, test split: open-loop prediction vs plant "
            f"(nu = {result.nu:.3f})")
    if not args.quiet:
        for s in ("train", "val", "test"):
            fits = ", ".join(f"{n} {f:.2f} %" for n, f in zip(names, scores[s]["fit"],
                                                             strict=True))
            print(f"{s:5s} FIT {fits}   max |error| {scores[s]['max_abs_err']:.4f}")
        print(f"nu = {result.nu:.4f}, ||U_o||_inf = {record['U_o_inf_norm']:.2f}, "
              f"best epoch {result.best_epoch} of {result.epochs_run}, "
              f"{record['wall_time_s']:.0f} s")
        print(f"wrote {out} and {figure}")
    return 0


def _named(names: list[str], values: list[float]) -> dict[str, float | None]:
    """``{output: value}``, a FIT that is not a number (a constant output) as None."""
    import math

    return {n: (float(v) if math.isfinite(v) else None)
            for n, v in zip(names, values, strict=True)}
