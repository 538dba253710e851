"""Training of a δISS GRU (``eq:gru``) with torch, in the paper's convention.

The paper (section V) trains on truncated subsequences of 500 steps with batch 5 and a
regulariser that penalises weights violating ``th:stability-bonassi`` (ν < 1). This module
keeps those settings as defaults and adds a stronger way to enforce the condition:

* ``constraint="project"`` (default): the forward pass uses weights rescaled so that
  ν ≤ 1 − margin holds *exactly*: with ``s = min(1, (1 − margin)/ν(θ))`` the recurrent
  matrices ``U_h`` and ``U_z`` are multiplied by ``s`` (ν is linear in ‖U_h‖∞ and
  super-linear in ‖U_z‖∞, so the rescaled weights satisfy ν ≤ s ν(θ) ≤ 1 − margin).
  Gradients flow through ``s``; after each optimiser step the raw weights are replaced by the
  rescaled ones (a projection), so every iterate, and the saved model, is δISS.
* ``constraint="penalty"``: the paper's soft regulariser ``w · relu(ν − (1 − margin))``.

By default ``U_z = 0`` (``train_uz=False``): in ν, ‖U_z‖∞ is multiplied by
¼(1 + φ̄_h)/(1 − σ̄_z), which is in the hundreds because the slow tanks need σ̄_z close to 1;
a trained ``U_z`` takes the whole ν budget for almost no gain and starves ``U_h``. An optional
cap on σ̄_z (``sigma_z_max``) bounds the contraction rates ρ_s, ρ_o used by the MPC, and an
optional penalty on ‖U_o‖∞ keeps the output matrix moderate: it multiplies every
constraint-tightening term of the MPC (``eq:constraint_tightening_parameters``).

A record may hold several experiments (:mod:`controllers.identification.sequences`): the
subsequences are cut inside one experiment's training rows, and the validation simulations
restart from ``x = 0`` at each experiment.

torch is imported inside the functions (it is an optional extra). Everything is float64 and
deterministic for a given seed (one thread).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from controllers import gru
from controllers.certification.bounds import nu as nu_numpy
from controllers.errors import DataError, DesignError, TrainingError
from controllers.identification import metrics, sequences
from controllers.identification.contraction import sigma_cap

__all__ = ["CONSTRAINED", "TrainOptions", "TrainResult", "build_model", "constrain", "init_params",
           "nu_torch", "subsequences", "train"]


@dataclass
class TrainOptions:
    """Settings of :func:`train` (recorded in the model file's ``training`` block).

    Attributes
    ----------
    n : int
        GRU states.
    seq_len : int
        Length of the truncated training subsequences (paper: 500; ``cosim train`` sets
        ``seq_len``, ``washout`` and ``batch`` from the record's length where not given:
        :func:`controllers.identification.sequences.record_defaults`).
    stride : int or None
        Offset between subsequence starts (``None``: ``seq_len``, non-overlapping, as the
        paper; smaller values overlap them).
    batch : int
        Subsequences per optimiser step (paper: 5; 0 = all of them).
    epochs : int
        Maximum passes over the training subsequences.
    lr, lr_final : float
        Adam learning rate, decayed geometrically to ``lr_final`` over ``epochs``.
    washout : int
        Steps at the start of each subsequence (from x = 0) excluded from the loss.
    nu_margin : float
        The trained model satisfies ν ≤ 1 − nu_margin (projection) or is pushed there
        (penalty).
    constraint : str
        ``project`` or ``penalty`` (see the module docstring).
    penalty_weight : float
        Weight of the ν penalty (``penalty``; also added with ``project`` when > 0).
    uo_weight, uo_max : float
        Penalty ``uo_weight · relu(‖U_o‖∞ − uo_max)`` on the output matrix.
    bz_init : float
        Initial update-gate bias (z ≈ σ(bz_init) near 1: slow tank dynamics).
    patience : int
        Early stopping: epochs without a better validation FIT (0 = off).
    rho_max : float
        With ``project``: also keep ρ_s = σ̄_z + (1 − σ̄_z) ν ≤ rho_max (0 = no cap;
        ``lem:Vs``; :func:`constrain`).
    sigma_z_max : float
        With ``project``: also keep σ̄_z ≤ sigma_z_max (0 = no cap). σ̄_z sets the
        contraction rates ρ_s, ρ_o of ``lem:Vs``/``lem:Vo``, hence the MPC's tightening.
    train_uz : bool
        Train ``U_z``. Default False: ``U_z`` stays zero and the whole ν budget goes to
        ``U_h``. With ``U_z`` trained, the term ¼(1 + φ̄_h)/(1 − σ̄_z)‖U_z‖∞ of ν (large,
        as σ̄_z is close to 1 for the slow tanks) takes the budget and ``U_h`` dies: measured
        test FIT 91.7/92.0 % vs 93.8/94.6 % after 300 epochs.
    eval_washout : int
        Validation FIT per epoch: the model runs open loop from x = 0 over this many steps
        before the validation split, then over the split.
    seed : int
    """

    n: int = 20
    seq_len: int = 500
    stride: int | None = None
    batch: int = 5
    epochs: int = 2000
    lr: float = 2e-2
    lr_final: float = 5e-4
    washout: int = 50
    nu_margin: float = 0.02
    constraint: str = "project"
    penalty_weight: float = 0.0
    uo_weight: float = 0.0
    uo_max: float = 5.0
    bz_init: float = 2.0
    patience: int = 0
    sigma_z_max: float = 0.0
    rho_max: float = 0.0
    train_uz: bool = False
    eval_washout: int = 1000
    seed: int = 0


@dataclass
class TrainResult:
    """Outcome of :func:`train`: the best weights on validation and the history."""

    params: dict[str, np.ndarray]
    nu: float
    best_epoch: int
    epochs_run: int
    wall_time: float
    history: list[dict[str, float]] = field(default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)


def nu_torch(p: dict[str, Any]) -> Any:
    """ν of ``th:stability-bonassi`` on torch tensors, differentiable (subgradients).

    Same expression as :func:`controllers.certification.bounds.nu`; ∞-norms are max row sums of
    absolute values.
    """
    import torch

    def norm(a: Any) -> Any:
        return a.abs().sum(dim=1).max()

    def row(g: str) -> Any:
        return norm(torch.cat([p[f"W_{g}"], p[f"U_{g}"], p[f"b_{g}"].reshape(-1, 1)], dim=1))

    s_z = torch.sigmoid(row("z"))
    s_r = torch.sigmoid(row("r"))
    p_h = torch.tanh(row("h"))
    return (norm(p["U_h"]) * (0.25 * norm(p["U_r"]) + s_r)
            + 0.25 * (1 + p_h) / (1 - s_z) * norm(p["U_z"]))


def constrain(p: dict[str, Any], target: float, sigma_z_max: float = 0.0,
              rho_max: float = 0.0) -> tuple[dict[str, Any], Any]:
    """Rescale the weights so that ν ≤ ``target`` (``th:stability-bonassi``), σ̄_z ≤
    ``sigma_z_max`` when > 0, and ρ_s = σ̄_z + (1 − σ̄_z) ν ≤ ``rho_max`` when > 0 (``lem:Vs``).

    First, every row of ``[W_z U_z b_z]`` whose absolute sum exceeds ``logit(cap)`` is scaled
    down to it (so σ̄_z ≤ cap), the cap the smaller of ``sigma_z_max`` and, with
    ``rho_max``, :func:`controllers.identification.contraction.sigma_cap`. Then ``U_h`` and
    ``U_z`` are multiplied by ``s = min(1, ν_max/ν)`` with ``ν_max = target``, or with
    ``rho_max`` the smaller of ``target`` and ``(rho_max − σ̄_z)/(1 − σ̄_z)``: ν is linear in
    ‖U_h‖∞ and super-linear in ‖U_z‖∞ (through σ̄_z and φ̄_h, which only shrink), so the
    result has ν ≤ ν_max. Differentiable (almost everywhere): used in the forward pass of
    :func:`train` and :func:`controllers.identification.simulation.fit_candidate`.

    Returns the rescaled weights and ν before the ν-rescaling.
    """
    import torch

    q = dict(p)
    caps = [c for c in (sigma_z_max, sigma_cap(rho_max) if rho_max > 0 else 0.0) if c > 0]
    if caps:
        cap = math.log(min(caps) / (1.0 - min(caps)))
        rows = (p["W_z"].abs().sum(dim=1) + p["U_z"].abs().sum(dim=1) + p["b_z"].abs())
        k = torch.clamp(cap / torch.clamp(rows, min=1e-300), max=1.0)
        q["W_z"] = p["W_z"] * k.reshape(-1, 1)
        q["U_z"] = p["U_z"] * k.reshape(-1, 1)
        q["b_z"] = p["b_z"] * k
    v = nu_torch(q)
    allowed: Any = target
    if rho_max > 0:   # ρ_s = σ̄_z + (1 − σ̄_z) ν ≤ rho_max (lem:Vs)
        sz = torch.sigmoid(torch.cat([q["W_z"], q["U_z"], q["b_z"].reshape(-1, 1)],
                                     dim=1).abs().sum(dim=1).max())
        allowed = torch.clamp((rho_max - sz) / (1.0 - sz), min=0.0, max=target)
    s = torch.clamp(allowed / v, max=1.0)
    q["U_h"] = q["U_h"] * s
    q["U_z"] = q["U_z"] * s
    return q, v


#: Weights that :func:`constrain` may change (copied back after each optimiser step).
CONSTRAINED = ("W_z", "U_z", "b_z", "U_h")


def init_params(n: int, m: int, p: int, seed: int, bz_init: float = 2.0,
                nu_init: float = 0.5) -> dict[str, np.ndarray]:
    """Initial weights satisfying ``th:stability-bonassi`` with ν ≤ ``nu_init``.

    Input weights and biases uniform ±1/√n (torch's GRU default), ``b_z = bz_init`` (slow
    update gate), small ``U_r`` and ``U_z``; ``U_h`` and ``U_z`` are then scaled down until
    ν ≤ ``nu_init``.
    """
    rng = np.random.default_rng(seed)
    k = 1.0 / math.sqrt(n)

    def uni(*shape: int, scale: float = k) -> np.ndarray:
        return rng.uniform(-scale, scale, size=shape)

    q = {"W_z": uni(n, m), "U_z": uni(n, n, scale=0.01 * k), "b_z": np.full(n, bz_init),
         "W_r": uni(n, m), "U_r": uni(n, n, scale=0.1 * k), "b_r": uni(n),
         "W_h": uni(n, m), "U_h": uni(n, n), "b_h": uni(n),
         "U_o": uni(p, n), "b_o": np.zeros(p)}
    v = nu_numpy(q)
    if v > nu_init:
        q["U_h"] *= nu_init / v
        q["U_z"] *= nu_init / v
    return q


def subsequences(T: int, seq_len: int, stride: int | None) -> list[int]:
    """Start indices of the truncated training subsequences of a record of length ``T``
    (one stretch: :func:`controllers.identification.sequences.subsequence_starts` for several)."""
    if seq_len > T:
        raise DataError(f"training data has {T} steps, fewer than seq_len = {seq_len}")
    stride = stride or seq_len
    return list(range(0, T - seq_len + 1, stride))


def _rollout(p: dict[str, Any], u: Any, x0: Any) -> Any:
    """Outputs (L, p, B) of ``eq:gru`` for inputs (L, m, B) from states (n, B)."""
    import torch

    ops = gru.torch_ops()
    q = {k: (v.reshape(-1, 1) if k.startswith("b") else v) for k, v in p.items()}
    x = x0
    outs = []
    for k in range(u.shape[0]):
        outs.append(gru.output(q, x))
        x = gru.step(q, x, u[k], ops)
    return torch.stack(outs)


def _subsequences(u_train: np.ndarray, y_train: np.ndarray, u_all: np.ndarray,
                  y_all: np.ndarray, split_all: np.ndarray, experiment: np.ndarray | None,
                  opt: TrainOptions) -> tuple[Any, Any]:
    """The training subsequences as ``(seq_len, m | p, count)`` float64 tensors, cut inside
    each training stretch (:func:`controllers.identification.sequences.stretches`); ``u_train``,
    ``y_train`` must be the record's training rows."""
    import torch

    n_train = int(np.count_nonzero(split_all == "train"))
    if u_train.shape[0] != n_train or y_train.shape[0] != n_train:
        raise DataError(f"u_train has {u_train.shape[0]} rows and y_train {y_train.shape[0]}, "
                        f"but the record has {n_train} training rows")
    spans = sequences.stretches(split_all, experiment, "train")
    starts = sequences.subsequence_starts(spans, opt.seq_len, opt.stride)
    U = torch.tensor(np.stack([u_all[s:s + opt.seq_len] for s in starts], axis=2),
                     dtype=torch.float64)
    Y = torch.tensor(np.stack([y_all[s:s + opt.seq_len] for s in starts], axis=2),
                     dtype=torch.float64)
    return U, Y


def _batch_loss(q: dict[str, Any], U: Any, Y: Any, opt: TrainOptions, target: float
                ) -> tuple[Any, Any]:
    """``(loss, regulariser)`` of one batch: the mean squared error of the rollouts from
    ``x = 0`` after the washout, and the ν and ``‖U_o‖∞`` penalties of the options."""
    import torch

    x0 = torch.zeros(opt.n, U.shape[2], dtype=torch.float64)
    err = (_rollout(q, U, x0) - Y)[opt.washout:]
    loss = (err ** 2).mean()
    reg: Any = 0.0
    if opt.constraint == "penalty" or opt.penalty_weight > 0:
        reg = reg + opt.penalty_weight * torch.relu(nu_torch(q) - target)
    if opt.uo_weight > 0:
        uo = q["U_o"].abs().sum(dim=1).max()
        reg = reg + opt.uo_weight * torch.relu(uo - opt.uo_max)
    return loss, reg


def train(u_train: np.ndarray, y_train: np.ndarray, u_all: np.ndarray, y_all: np.ndarray,
          split_all: np.ndarray, options: TrainOptions | None = None, progress: bool = True,
          init: dict[str, np.ndarray] | None = None,
          callback: Callable[[int, dict[str, Any], dict[str, np.ndarray]], None] | None = None,
          experiment: np.ndarray | None = None) -> TrainResult:
    """Train a GRU on normalised data; select the epoch with the best validation FIT.

    Parameters
    ----------
    u_train, y_train : (T, m), (T, p) arrays
        Normalised training inputs and outputs: the rows of ``u_all``, ``y_all`` whose split
        is ``train`` (checked). The subsequences are cut from ``u_all``, ``y_all`` inside each
        training stretch (:func:`controllers.identification.sequences.stretches`), never across two
        experiments or over validation and test rows.
    u_all, y_all, split_all : arrays
        The whole normalised record with its split labels: validation FIT is computed by an
        open-loop simulation over it, restarted at each experiment
        (:func:`controllers.identification.sequences.eval_windows`).
    options : TrainOptions
    progress : bool
        Show a tqdm bar with loss, validation FIT and ν per epoch.
    init : dict of arrays, optional
        Initial weights (default :func:`init_params`).
    callback : callable, optional
        Called as ``callback(epoch, record, weights)`` after each epoch (``weights``: the
        constrained numpy weights of that epoch).
    experiment : (T,) array, optional
        The experiment of each row of the record (consecutive rows; default: one experiment).

    Raises
    ------
    DataError
        ``u_train`` is not the record's training rows, or no training stretch is as long as
        ``options.seq_len``.
    """
    import torch
    from tqdm import tqdm

    opt = options or TrainOptions()
    if opt.constraint not in ("project", "penalty"):
        raise DesignError(f"unknown constraint mode {opt.constraint!r} (project or penalty)")
    torch.set_num_threads(1)
    torch.manual_seed(opt.seed)
    rng = np.random.default_rng(opt.seed)
    target = 1.0 - opt.nu_margin
    p0 = init or init_params(opt.n, u_train.shape[1], y_train.shape[1], opt.seed, opt.bz_init)
    params = trainable_params(p0, opt.train_uz,
                              target if opt.constraint == "project" else None, opt.sigma_z_max,
                              opt.rho_max)
    split_all = np.asarray(split_all)
    U, Y = _subsequences(u_train, y_train, u_all, y_all, split_all, experiment, opt)
    optimiser = torch.optim.Adam([v for v in params.values() if v.requires_grad], lr=opt.lr)
    gamma = (opt.lr_final / opt.lr) ** (1.0 / max(1, opt.epochs - 1))
    scheduler = torch.optim.lr_scheduler.ExponentialLR(optimiser, gamma)
    validation_fit = _validation(u_all, y_all, split_all, experiment, opt)

    best: dict[str, np.ndarray] | None = None
    best_score, best_epoch, history = -np.inf, -1, []
    t0 = time.perf_counter()
    bar = tqdm(range(opt.epochs), desc="train", unit="epoch", disable=not progress)
    for epoch in bar:
        loss = _epoch(params, U, Y, optimiser, rng, opt, target)
        scheduler.step()
        pn = _numpy_params(params, opt, target)
        fit = validation_fit(pn)
        nu_val = nu_numpy(pn)
        record = {"epoch": epoch, "loss": loss, "nu": nu_val,
                  "fit_val": [float(f) for f in fit],
                  "uo_norm": float(np.max(np.sum(np.abs(pn["U_o"]), axis=1))),
                  "time": time.perf_counter() - t0}
        history.append(record)
        score = float(np.mean(fit))
        if nu_val < 1.0 and score > best_score:
            best, best_score, best_epoch = pn, score, epoch
        bar.set_postfix(loss=f"{loss:.2e}", fit="/".join(f"{f:.1f}" for f in fit),
                        nu=f"{nu_val:.3f}")
        if callback is not None:
            callback(epoch, record, pn)
        if opt.patience and epoch - best_epoch >= opt.patience:
            break
    bar.close()
    if best is None:
        best = _numpy_params(params, opt, target)
    return TrainResult(params=best, nu=nu_numpy(best), best_epoch=best_epoch,
                       epochs_run=len(history), wall_time=time.perf_counter() - t0,
                       history=history, options=asdict(opt))


def project(params: dict[str, Any], target: float, sigma_z_max: float,
            rho_max: float = 0.0) -> None:
    """Project the trainable weights onto ``ν ≤ target`` (and ``σ̄_z ≤ sigma_z_max``,
    ``ρ_s ≤ rho_max``) in place: :func:`constrain` of :data:`CONSTRAINED`."""
    import torch

    with torch.no_grad():
        q, _ = constrain(params, target, sigma_z_max, rho_max)
        for k in CONSTRAINED:
            params[k].copy_(q[k])


def trainable_params(p0: dict[str, np.ndarray], train_uz: bool, target: float | None,
                     sigma_z_max: float = 0.0, rho_max: float = 0.0) -> dict[str, Any]:
    """The trainable float64 tensors from the weights ``p0``: ``U_z = 0`` (not trained)
    unless ``train_uz``; projected onto ``ν ≤ target`` unless ``target`` is None."""
    import torch

    params = {k: torch.tensor(np.asarray(v, dtype=float), dtype=torch.float64,
                              requires_grad=True) for k, v in p0.items()}
    if not train_uz:
        params["U_z"] = torch.zeros_like(params["U_z"])
    if target is not None:
        project(params, target, sigma_z_max, rho_max)
    return params


def _effective(params: dict[str, Any], opt: TrainOptions, target: float
               ) -> tuple[dict[str, Any], Any]:
    """The weights the loss sees and their ν: projected, or as they are (penalty mode)."""
    if opt.constraint == "project":
        return constrain(params, target, opt.sigma_z_max, opt.rho_max)
    return params, nu_torch(params)


def _numpy_params(params: dict[str, Any], opt: TrainOptions, target: float
                  ) -> dict[str, np.ndarray]:
    """The effective weights as numpy arrays (copies)."""
    import torch

    with torch.no_grad():
        q, _ = _effective(params, opt, target)
        return {k: v.detach().numpy().copy() for k, v in q.items()}


def _epoch(params: dict[str, Any], U: Any, Y: Any, optimiser: Any,
           rng: np.random.Generator, opt: TrainOptions, target: float) -> float:
    """One pass over the subsequences in shuffled batches; the mean batch loss."""
    import torch

    count = U.shape[2]
    batch = opt.batch if 0 < opt.batch <= count else count
    n_batches = math.ceil(count / batch)
    order = rng.permutation(count)
    total = 0.0
    for b in range(n_batches):
        idx = torch.as_tensor(order[b * batch:(b + 1) * batch])
        q, _ = _effective(params, opt, target)
        loss, reg = _batch_loss(q, U[:, :, idx], Y[:, :, idx], opt, target)
        total += loss.item()
        optimiser.zero_grad()
        (loss + reg).backward()
        optimiser.step()
        if opt.constraint == "project":
            project(params, target, opt.sigma_z_max, opt.rho_max)
    return total / n_batches


def _validation(u_all: np.ndarray, y_all: np.ndarray, split_all: np.ndarray,
                experiment: np.ndarray | None, opt: TrainOptions
                ) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
    """The validation FIT of a set of weights (model selection): open loop from ``x = 0`` in
    each experiment, starting ``eval_washout`` steps before its validation rows so that the
    initial transient has died out; the validation rows of every experiment scored together
    (the training rows when there are none)."""
    scored = "val" if np.any(split_all == "val") else "train"
    windows = sequences.eval_windows(split_all, experiment, scored, opt.eval_washout)
    y_val = np.concatenate([y_all[a:b][split_all[a:b] == scored] for a, b in windows])

    def validation_fit(pn: dict[str, np.ndarray]) -> np.ndarray:
        xi = np.concatenate([metrics.open_loop(pn, u_all[a:b])[split_all[a:b] == scored]
                             for a, b in windows])
        return metrics.fit(y_val, xi)

    return validation_fit


def build_model(params: dict[str, np.ndarray], problem: Any,
                training_record: dict[str, Any], w_y_bar: float | None = None) -> Any:
    """A :class:`controllers.model.GRUModel` from trained weights for the control problem
    ``problem`` (its signals, sample time and normalisation, recorded in the model file);
    refuses ν ≥ 1.

    Raises
    ------
    TrainingError
        When the weights violate ``th:stability-bonassi`` (ν ≥ 1): such a model carries no
        δISS certificate and the MPC's guarantees would not hold.
    """
    from controllers.model import GRUModel

    norm = problem.normalization()
    v = nu_numpy(params)
    if not v < 1.0:
        raise TrainingError(f"trained model has nu = {v:.4f} >= 1 (th:stability-bonassi fails); "
                            "not saved: train longer, raise nu_margin or use constraint "
                            "'project'")
    return GRUModel(params={k: np.asarray(a, dtype=float) for k, a in params.items()},
                    u_offset=norm["u_offset"], u_scale=norm["u_scale"],
                    y_offset=norm["y_offset"], y_scale=norm["y_scale"],
                    input_names=list(problem.model_input_names),
                    input_units=[c.unit for c in problem.model_inputs],
                    output_names=list(problem.output_names),
                    output_units=list(problem.output_units), Ts=float(problem.Ts),
                    training=training_record, w_y_bar=w_y_bar, problem=problem)
