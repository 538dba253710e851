"""The two training methods of ``cosim train`` and what follows them (scores, model file,
figure, report): :func:`simulation` (the default), :func:`truncated` (the paper's recipe),
:func:`finish`."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Trained", "finish", "simulation", "truncated"]


@dataclass
class Trained:
    """A training's outcome: the weights, ν, what goes into the model file's ``training``
    block, and the ``--history`` lines (``None``: written as training went)."""

    params: dict[str, np.ndarray]
    nu: float
    record: dict[str, Any]
    history: list[str] | None = None
    label: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def _bar(total: int, progress: bool, unit: str) -> Any:
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc="train", unit=unit, disable=not progress, file=sys.stderr,
                dynamic_ncols=True)


def _init(args: argparse.Namespace, problem: Any) -> dict[str, np.ndarray] | None:
    """``--init``'s weights, checked against the problem (and ``--n``)."""
    from controllers.model import GRUModel
    from cosim.core.errors import CosimError

    if not args.init:
        return None
    start = GRUModel.load(args.init)
    m = len(problem.model_inputs)
    if start.m != m or start.p != problem.p:
        raise CosimError(f"{args.init}: model has m={start.m}, p={start.p}, but the problem "
                         f"has {m} model inputs and {problem.p} outputs")
    if args.n is not None and start.n != args.n:
        raise CosimError(f"{args.init}: model has n={start.n}, but --n is {args.n}")
    return start.params


def simulation(args: argparse.Namespace, data: Any, record: Any, problem: Any,
               progress: bool) -> Trained:
    """Candidates of sizes and seeds fitted on simulation error, the best on validation
    (:func:`controllers.identification.search.search`)."""
    from controllers.identification.search import DEFAULT_SEEDS, planned_steps, search
    from controllers.identification.simulation import (
        SimOptions,
        default_epochs,
        default_polish,
    )

    init = _init(args, problem)
    default = default_epochs(record, args.window)
    epochs = args.epochs if args.epochs is not None else default
    # the polish follows a shorter --epochs in proportion (a quick run stays quick)
    polish = (round(default_polish(record) * min(1.0, epochs / default))
              if args.polish is None else args.polish)
    sizes = [int(init["W_z"].shape[0])] if init is not None else args.size_list
    seeds = args.seeds or (1 if init is not None or args.n is not None else DEFAULT_SEEDS)
    rho_max, contraction, arx = _contraction(args, record)
    base = SimOptions(epochs=epochs, lr=args.lr, lr_final=args.lr_final,
                      window=args.window, nu_margin=args.nu_margin,
                      sigma_z_max=args.sigma_z_max, rho_max=rho_max, train_uz=args.train_uz,
                      bz_init=args.bz_init, x0_samples=args.x0_samples,
                      patience=args.patience,
                      polish=polish, seed=args.seed)
    # a derived cap is tried beside none: kept unless the uncapped fit is better
    loose = 0.0 if contraction["source"] == "ARX baseline" and rho_max > 0 else None
    bar = _bar(planned_steps(base, sizes, seeds, loose), progress, "step")
    try:
        res = search(record, base, sizes, seeds, args.workers,
                     progress=lambda done: bar.update(done - bar.n), init=init, loose=loose)
    finally:
        bar.close()
    best = res.best
    history = ["n,seed,rho_max,step,time_s,score_rms\n"] + [
        f"{t['n']},{t['seed']},{t['rho_max']:g},{h['step']},{h['time']:.2f},{h['score']:.6e}\n"
        for t in res.tried for h in t["history"]]
    tried = [{k: v for k, v in t.items() if k != "history"} for t in res.tried]
    adam = base.steps
    rec = {"method": "simulation", "options": best.options, "best_step": best.best_step,
           "steps_run": best.steps_run, "epochs_run": min(best.steps_run, adam) // 6,
           "best_epoch": min(best.best_step, adam) // 6,
           "polish_iterations": max(0, best.steps_run - adam),
           "contraction": {**contraction, **res.caps}, "candidates": tried,
           "selection": ("lowest validation RMS of the free run (normalised, averaged over "
                         "the outputs)" if record.has("val") else
                         "lowest training RMS of the free run (no validation rows)")}
    label = f"GRU n={best.options['n']} (best of {len(tried)} candidates)"
    return Trained(best.params, best.nu, rec, history, label,
                   {} if arx is False else {"arx": arx})


def _contraction(args: argparse.Namespace, record: Any
                 ) -> tuple[float, dict[str, Any], Any]:
    """The contraction cap ρ_max of the training (``lem:Vs``): ``--rho-max`` (or the problem's
    ``[train] rho_max``) when given, else derived from the ARX baseline's slowest pole
    (:func:`controllers.identification.contraction.rho_max`); its record for the model file;
    the ARX baseline (``False``: not fitted here)."""
    from controllers.identification import contraction, linear

    if args.rho_max is not None:
        return float(args.rho_max), {"rho_max": float(args.rho_max), "source": "given"}, False
    arx = linear.fit_arx(record)
    rho = contraction.rho_max(arx)
    pole = None if arx is None else contraction.slowest_pole(arx)
    return rho, {"rho_max": rho, "source": "ARX baseline", "slowest_pole": pole,
                 "slack": contraction.SLACK}, arx


def truncated(args: argparse.Namespace, data: Any, record: Any, problem: Any,
              progress: bool) -> Trained:
    """The paper's recipe (:func:`controllers.identification.training.train`): truncated
    subsequences from ``x = 0``, the epoch with the best validation FIT; ``--history`` written
    as it goes."""
    import contextlib

    from controllers.identification import sequences, training
    from cosim.core.errors import CosimError

    spans = sequences.stretches(data.split, data.experiment, "train")
    lengths = [b - a for a, b in spans]
    auto = sequences.record_defaults(lengths, args.seq_len, args.washout, args.batch,
                                     args.stride)
    if auto.subsequences == 0:
        raise CosimError(f"{args.data[0]}: the longest training stretch has {max(lengths)} "
                         f"steps (of {sum(lengths)} training rows), fewer than --seq-len "
                         f"{auto.seq_len}")
    if not 0 <= auto.washout < auto.seq_len:
        raise CosimError(f"--washout must be in [0, --seq-len), got {auto.washout}")
    penalty = args.penalty_weight
    if penalty is None:
        penalty = 10.0 if args.constraint == "penalty" else 0.0
    n = args.n if args.n is not None else training.TrainOptions().n
    opts = training.TrainOptions(
        n=n, seq_len=auto.seq_len, stride=args.stride, batch=auto.batch,
        epochs=args.epochs, lr=args.lr, lr_final=args.lr_final, washout=auto.washout,
        nu_margin=args.nu_margin, constraint=args.constraint, penalty_weight=penalty,
        uo_weight=args.uo_weight, uo_max=args.uo_max, bz_init=args.bz_init,
        patience=args.patience, sigma_z_max=args.sigma_z_max, rho_max=args.rho_max or 0.0,
        train_uz=args.train_uz, seed=args.seed)
    init = _init(args, problem)
    if init is not None and init["W_z"].shape[0] != opts.n:
        raise CosimError(f"{args.init}: model has n={init['W_z'].shape[0]}, but --n is "
                         f"{opts.n}")
    train_mask = data.split == "train"
    with contextlib.ExitStack() as stack:
        callback = (_history_log(stack, Path(args.history), list(problem.output_names))
                    if args.history else None)
        result = training.train(record.u[train_mask], record.y[train_mask], record.u,
                                record.y, data.split, opts, progress=progress, init=init,
                                callback=callback, experiment=data.experiment)
    rec = {"method": "truncated", "epochs_run": result.epochs_run,
           "best_epoch": result.best_epoch, "options": result.options,
           "subsequences": {"count": auto.subsequences, "training_stretches": len(spans),
                            "from_record": [o for o, v in (("seq_len", args.seq_len),
                                                           ("washout", args.washout),
                                                           ("batch", args.batch))
                                            if v is None]}}
    return Trained(result.params, result.nu, rec, None, f"GRU n={opts.n}")


def _history_log(stack: Any, history: Path, names: list[str]) -> Any:
    """The epoch callback of :func:`truncated` writing ``--history`` as training goes (a
    temporary file entered into ``stack``, an ``ExitStack``, renamed onto ``history`` when it
    closes)."""
    from cosim.core.atomicio import open_replacing, output_error

    fh = stack.enter_context(open_replacing(history, "w", newline=""))

    def log(line: str) -> None:
        try:
            fh.write(line)
            fh.flush()
        except OSError as exc:
            raise output_error(history, exc) from None

    log("epoch,time_s,loss,nu," + "".join(f"fit_val_{n}," for n in names) + "U_o_inf_norm\n")

    def callback(epoch: int, rec: dict, _weights: dict) -> None:
        log(f"{epoch},{rec['time']:.2f},{rec['loss']:.6e},{rec['nu']:.6f},"
            + "".join(f"{f:.4f}," for f in rec["fit_val"]) + f"{rec['uo_norm']:.4f}\n")

    return callback


def _prediction_error(record: Any, ev: Any, problem: Any, params: dict[str, np.ndarray]
                      ) -> tuple[Any, dict[str, Any]]:
    """The model's measured prediction error on held-back rows (val and test, else train;
    :func:`controllers.certification.prediction_error.error_profile`: what the uncertified mode
    tightens by) with the offset filter measured on the whole record
    (:func:`~controllers.certification.prediction_error.offset_filter`; the law's default
    where it cannot be), and its summary for the model file, in the outputs' units."""
    from controllers.certification.prediction_error import error_profile, offset_filter
    from controllers.laws.tracking import SPEC as TRACKING

    held = np.isin(record.split, ("val", "test"))
    rows = held if np.any(held) else record.split == "train"
    # every row: the free run does not follow the noise on the rows it was fitted to either
    measured = offset_filter(record.y, ev.xi, record.experiments())
    beta = measured.beta if measured else TRACKING.defaults["offset_filter"]
    ahead = None
    if problem.q:   # the controller's prediction holds the measured disturbances
        from controllers.certification.prediction_error import held_predictions
        from controllers.identification.simulation import free_run_states

        x = free_run_states(params, record, ev.starts)   # the scored free run's states
        ahead = held_predictions(params, record.u, x, problem.q, record.experiments())
    profile = error_profile(record.y, ev.xi, rows, record.experiments(), beta, ahead=ahead)
    scale = problem.normalization()["y_scale"]
    last = 0 if profile is None else len(profile) - 1

    def units(values: Any) -> dict[str, float] | None:
        if values is None:
            return None
        return {n: float(v * abs(s)) for n, v, s in zip(problem.output_names, values, scale,
                                                        strict=True)}

    return profile, {"rows": "val+test" if np.any(held) else "train",
                     "offset_filter": beta,
                     "offset_filter_from": "measured" if measured else "default",
                     "sensor_noise": units(measured.noise) if measured else None,
                     "mismatch_drift": units(measured.drift) if measured else None,
                     "steps": None if profile is None else int(profile.shape[0]),
                     "at_1_step": None if profile is None else units(profile[min(1, last)]),
                     "at_last_step": None if profile is None else units(profile[-1])}


def _with_offset_filter(problem: Any, summary: dict[str, Any]) -> Any:
    """``problem`` with the measured offset filter in its ``[mpc]`` table, which every run of
    the model reads (:meth:`controllers.mpc_options.MPCOptions.resolve`), unless the problem
    file gives one (its own choice kept)."""
    import dataclasses

    if summary["offset_filter_from"] != "measured" or "offset_filter" in problem.mpc:
        return problem
    return dataclasses.replace(problem, mpc={**problem.mpc,
                                             "offset_filter": summary["offset_filter"]})


def _rates(data: Any, problem: Any) -> dict[str, float]:
    """Each measured disturbance's largest change per sample in the data (within an
    experiment), in its units: the held disturbance's tightening when the problem gives no
    ``rate`` (:func:`controllers.disturbances.rates`)."""
    out = {}
    same = data.experiment[1:] == data.experiment[:-1]
    for j, c in enumerate(problem.disturbances, start=problem.m):
        steps = np.abs(np.diff(data.u[:, j]))[same]
        out[c.name] = float(np.max(steps)) if steps.size else 0.0
    return out


def _model_record(args: argparse.Namespace, data: Any, record: Any, trained: Trained,
                  ev: Any, wall: float, command: str, sidecar: dict | None) -> dict[str, Any]:
    """The model file's ``training`` record: the command, data, scores against the
    baseline, the free-run protocol and the δISS bounds."""
    from controllers.certification import bounds

    sz, sr, ph = bounds.gate_bounds(trained.params)
    return {
        "command": command,
        "data": [str(p) for p in (*args.data, *args.val, *args.test)],
        "data_meta": sidecar,
        "data_file": data.provenance,
        "seed": args.seed,
        "init": args.init,
        **trained.record,
        "scores": ev.scores,
        "baseline": None if ev.baseline is None else {"model": "ARX", **ev.baseline_orders,
                                                      "scores": ev.baseline},
        "comparison": ev.comparison,
        **({"without_disturbances": ev.disturbances} if ev.disturbances else {}),
        "worse_than_baseline": ev.warning is not None,
        "sensor_limits": ev.limits,
        "fit": {s: d["fit"] for s, d in ev.scores["splits"].items()},
        "max_abs_err": {s: float(np.max(np.abs(record.y - ev.xi)[record.split == s]))
                        for s in ev.scores["splits"]},
        "w_y_bar_split": _scored_split(record),
        "fit_protocol": ("free-run simulation of each experiment from the initial state "
                         f"estimated from its first {args.x0_samples} samples, read through "
                         "the sensor limits; RMS in the outputs' units, FIT per split on its "
                         "rows of every experiment"),
        "nu": trained.nu,
        "sigma_z_bar": sz, "sigma_r_bar": sr, "phi_h_bar": ph,
        "U_o_inf_norm": bounds.inf_norm(trained.params["U_o"]),
        "normalization_note": "(value - offset) / scale, offset and scale per signal from "
                              "the problem (default: middle and half-width of its box)",
        "wall_time_s": round(wall, 1),
        "torch_version": __import__("torch").__version__,
    }


def _scored_split(record: Any) -> str:
    """The split whose worst output error is the model's w̄_y: test, else val, else train."""
    return next(s for s in ("test", "val", "train") if np.any(record.split == s))


def _write_history(path: str | None, history: list[str] | None) -> None:
    """The ``--history`` CSV (atomic), when asked for and kept."""
    from cosim.core.atomicio import output_error, replacing

    if history is None or not path:
        return
    try:
        with replacing(path) as tmp:
            Path(tmp).write_text("".join(history), encoding="utf-8")
    except OSError as exc:
        raise output_error(path, exc) from None


def finish(args: argparse.Namespace, data: Any, record: Any, problem: Any, trained: Trained,
           out: Path, figure: Path, wall: float, command: str, sidecar: dict | None) -> int:
    """Score the model against its baseline, write the model file, the figure and the
    ``--history``; print the report."""
    from controllers.identification import training
    from cosim.commands import train_report
    from cosim.core.atomicio import output_error, replacing

    ev = train_report.evaluate(trained.params, record, problem, data.experiment_names,
                               args.x0_samples, trained.extra.get("arx", False))
    err = np.abs(record.y - ev.xi)[record.split == _scored_split(record)]
    doc = _model_record(args, data, record, trained, ev, wall, command, sidecar)
    profile, doc["prediction_error"] = _prediction_error(record, ev, problem, trained.params)
    problem = _with_offset_filter(problem, doc["prediction_error"])
    if problem.q:
        doc["disturbance_rates"] = _rates(data, problem)
    model = training.build_model(trained.params, problem, doc, w_y_bar=float(np.max(err)))
    model.prediction_error = profile
    try:
        model.save(out)   # atomic: a failed write leaves the previous file unchanged
    except OSError as exc:
        raise output_error(out, exc) from None
    _write_history(args.history, trained.history)
    logged = sidecar is None or len(args.data) > 1 or bool(args.val or args.test)
    with replacing(figure) as tmp_figure:
        train_report.figure(tmp_figure, ev, record, model, logged,
                            f"{trained.label}, nu = {trained.nu:.3f}: free runs over the data")
    if not args.quiet:
        train_report.print_report(ev, list(problem.output_names), list(problem.output_units))
        print(f"nu = {trained.nu:.4f}, ||U_o||_inf = {doc['U_o_inf_norm']:.2f}, "
              f"{trained.label}, {doc['wall_time_s']:.0f} s")
        print(f"wrote {out} and {figure}")
    elif ev.warning:
        import sys

        print(f"cosim train: warning: {ev.warning}", file=sys.stderr)
    return 0
