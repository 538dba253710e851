"""Identification of a δISS GRU (``eq:gru``) by simulation error, with estimated initial states.

One candidate model (one size, one seed) is fitted by :func:`fit_candidate`:

* **Windows with free initial states.** The training rows are cut into windows (each training
  stretch whole up to :data:`MAX_WINDOW` rows, else in equal pieces of about
  :data:`LONG_WINDOW`), and each window's initial state ``x_0`` is a decision variable beside
  the weights (bounded to the GRU's state box [−1, 1]). The loss is the squared simulation
  error over every sample of every window: the model is never asked to reproduce a transient
  from ``x = 0`` that the plant did not have, which on a short record (the transient of a slow
  plant is a large share of a thousand samples) is what a washout of a tenth of a subsequence
  cannot prevent.
* **δISS at every step.** The weights are those of
  :func:`controllers.identification.training.constrain`: ν ≤ 1 − margin exactly
  (``th:stability-bonassi``), by projection, as the paper's training, and the contraction
  ρ_s = σ̄_z + (1 − σ̄_z) ν of ``lem:Vs`` at most :attr:`SimOptions.rho_max`
  (:mod:`controllers.identification.contraction`).
* **The gradient in C.** Loss and gradient come from :mod:`controllers.identification.
  sim_loss` (backpropagation through time, some hundred times torch's autograd); torch maps
  them through the projection and runs Adam on batches of the windows, then L-BFGS on all of
  them (:mod:`controllers.identification.polish`: Adam finds the basin, L-BFGS settles in it).
* **Selection on simulation.** Every :attr:`SimOptions.eval_every` steps the model is run
  free over the whole record, each experiment from an initial state estimated from its first
  samples (:mod:`controllers.identification.initial_state`), read through the sensor limits;
  the step with the lowest validation RMS (normalised, averaged over the outputs) is kept.

Sensor limits (:mod:`controllers.identification.saturation`) enter the loss as one-sided
errors. Everything is float64 and deterministic for a seed.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from controllers import gru
from controllers.certification.bounds import nu as nu_numpy
from controllers.identification.initial_state import (
    DEFAULT_SAMPLES,
    estimate_initial_state,
    free_run,
)
from controllers.identification.record import SPLITS, Record
from controllers.identification.sim_loss import SimLoss, unpack

__all__ = ["LONG_WINDOW", "MAX_WINDOW", "POLISH", "STEPS_PER_EPOCH", "Candidate", "SimOptions",
           "default_epochs", "default_polish", "fit_candidate", "free_run_states", "rms",
           "simulate", "single_threaded", "training_windows"]

#: A training stretch up to this many rows is one window...
MAX_WINDOW = 2000
#: ... a longer one is cut into windows of about this many rows (as many whole ones as fit,
#: the stretch shared equally between them: windows of one length waste no padding when
#: simulated side by side).
LONG_WINDOW = 1000
#: Adam steps per epoch (the paper's recipe: 30 subsequences in batches of 5).
STEPS_PER_EPOCH = 6
#: Default epochs: as many as make Adam's steps simulate :data:`EPOCH_ROWS` rows (an epoch
#: simulates the training rows once, or six times when there are fewer than six windows), at
#: least :data:`MIN_EPOCHS`, at most :data:`MAX_EPOCHS`. L-BFGS does the rest: on the
#: 1,000-sample heater of the tests, 167 epochs and L-BFGS simulated the validation rows as
#: well as 1,000 epochs and L-BFGS (0.09-0.11 degC) in 40 % of the time.
EPOCH_ROWS, MIN_EPOCHS, MAX_EPOCHS = 1_000_000, 150, 3000
#: L-BFGS iterations after Adam by default (:mod:`controllers.identification.polish`):
#: :data:`POLISH_ROWS` row-passes over the training rows, inside [:data:`MIN_POLISH`,
#: :data:`POLISH`] ...
POLISH_ROWS, MIN_POLISH, POLISH = 9_000_000, 500, 2000
#: ... stopped after this many without a better validation score.
POLISH_PATIENCE = 1000
#: Evaluations of the validation free run over a training (an evaluation costs some hundred
#: steps: the initial states' estimates and a free run of the whole record) ...
EVALUATIONS = 200
#: ... at most one every this many steps.
MIN_EVAL_EVERY = 25


@dataclass
class SimOptions:
    """Settings of :func:`fit_candidate` (recorded in the model file's ``training`` block).

    Attributes
    ----------
    n : int
        GRU states.
    epochs : int
        Passes over the training windows, each of :data:`STEPS_PER_EPOCH` Adam steps on a
        batch of the windows (a sixth of them; all of them, when there are fewer than six).
    polish : int
        L-BFGS iterations on all the windows after Adam (:mod:`controllers.identification.
        polish`; 0: none), stopped after :data:`POLISH_PATIENCE` without a better score.
    rho_max : float
        Keep ρ_s ≤ rho_max (``lem:Vs``; 0: no cap), as
        :class:`controllers.identification.training.TrainOptions`.
    lr, lr_final : float
        Adam's learning rate, decayed geometrically to ``lr_final`` over the steps.
    window : int
        Training window length (0: :data:`MAX_WINDOW` / :data:`LONG_WINDOW`).
    nu_margin, sigma_z_max, train_uz, bz_init
        As :class:`controllers.identification.training.TrainOptions`.
    x0_samples : int
        Samples of each experiment that estimate its initial state in the evaluations.
    eval_every : int
        Steps between two evaluations of the validation RMS, at least (0: the steps spread
        over :data:`EVALUATIONS` evaluations, at least :data:`MIN_EVAL_EVERY` apart).
    patience : int
        Stop after this many epochs without a better validation RMS (0: off).
    seed : int
    """

    n: int = 8
    epochs: int = 1000
    lr: float = 0.03
    lr_final: float = 0.003
    window: int = 0
    nu_margin: float = 0.02
    sigma_z_max: float = 0.0
    rho_max: float = 0.0
    train_uz: bool = False
    bz_init: float = 2.0
    x0_samples: int = DEFAULT_SAMPLES
    eval_every: int = 0
    patience: int = 0
    polish: int = POLISH
    seed: int = 0

    @property
    def steps(self) -> int:
        """Adam steps: ``epochs`` × :data:`STEPS_PER_EPOCH`."""
        return self.epochs * STEPS_PER_EPOCH

    @property
    def total(self) -> int:
        """Adam steps and L-BFGS iterations, at most: what :func:`fit_candidate`'s progress
        counts to."""
        return self.steps + self.polish


@dataclass
class Candidate:
    """One fitted candidate: its best weights on validation and how it got there."""

    params: dict[str, np.ndarray]
    nu: float
    score: float
    best_step: int
    steps_run: int
    wall_time: float
    options: dict[str, Any]
    history: list[dict[str, float]] = field(default_factory=list)


def default_epochs(record: Record, window: int = 0) -> int:
    """The epochs whose Adam steps simulate :data:`EPOCH_ROWS` rows (the training windows of
    ``window``, :func:`training_windows`), inside [:data:`MIN_EPOCHS`, :data:`MAX_EPOCHS`]."""
    spans = training_windows(record, window)
    rows = max(1, sum(b - a for a, b in spans))
    passes = STEPS_PER_EPOCH / max(1, min(STEPS_PER_EPOCH, len(spans)))
    return int(min(MAX_EPOCHS, max(MIN_EPOCHS, round(EPOCH_ROWS / (rows * passes)))))


def default_polish(record: Record) -> int:
    """:data:`POLISH_ROWS` over the record's training rows, inside [:data:`MIN_POLISH`,
    :data:`POLISH`]: an iteration simulates every training row."""
    rows = max(1, int(np.count_nonzero(record.split == "train")))
    return int(min(POLISH, max(MIN_POLISH, round(POLISH_ROWS / rows))))


def training_windows(record: Record, window: int = 0) -> list[tuple[int, int]]:
    """``(start, end)`` rows of the training windows: each training stretch whole when it
    has at most ``window`` rows (0: :data:`MAX_WINDOW`), else cut into ``k`` windows of equal
    length (to a row), ``k`` the number of whole ``window``-row pieces (0:
    :data:`LONG_WINDOW`) it holds."""
    whole = window or MAX_WINDOW
    piece = window or LONG_WINDOW
    out = []
    for a, b in record.stretches("train"):
        if b - a <= whole:
            out.append((a, b))
            continue
        k = (b - a) // piece
        cuts = [a + (i * (b - a)) // k for i in range(k)] + [b]
        out.extend(itertools.pairwise(cuts))
    return out


def simulate(params: dict[str, np.ndarray], record: Record,
             samples: int = DEFAULT_SAMPLES,
             starts: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """The model's free run over the record (T, p), each experiment from the initial state
    estimated from its first ``samples`` rows, read through the sensor limits. ``starts``
    (by experiment index), when given, holds where each estimate starts and receives the
    estimates (the evaluations during training warm start from the last ones)."""
    xi = np.empty_like(record.y)
    for e, (a, b) in enumerate(record.experiments()):
        x0 = estimate_initial_state(params, record.u[a:b], record.y[a:b], record.sat[a:b],
                                    samples, start=None if starts is None else starts.get(e))
        if starts is not None:
            starts[e] = x0
        xi[a:b] = free_run(params, record.u[a:b], x0)
    return record.limits.clip(xi)


def free_run_states(params: dict[str, np.ndarray], record: Record,
                    starts: dict[int, np.ndarray]) -> np.ndarray:
    """The states of :func:`simulate`'s free run, ``(T, n)``: row ``k`` is ``x_k``, from
    which ``ξ_k`` is read, each experiment from the initial state :func:`simulate` estimated
    for it (its ``starts``)."""
    x = np.empty((len(record.y), params["U_z"].shape[0]))
    for e, (a, b) in enumerate(record.experiments()):
        x[a:b] = gru.simulate(params, starts[e], record.u[a:b])[0][:-1]
    return x


def rms(record: Record, xi: np.ndarray, rows: np.ndarray | None = None
        ) -> dict[str, np.ndarray]:
    """RMS of ``y − ξ`` per output (normalised) for each split with rows (among ``rows``)."""
    keep = np.ones(len(record.y), dtype=bool) if rows is None else np.asarray(rows, bool)
    out = {}
    for name in SPLITS:
        mask = keep & (record.split == name)
        if np.any(mask):
            out[name] = np.sqrt(np.mean((record.y[mask] - xi[mask]) ** 2, axis=0))
    return out


def _scored(record: Record) -> str:
    return "val" if record.has("val") else "train"


def window_arrays(record: Record, window: int | None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The training windows (:func:`training_windows`) as ``(U, Y, W, S)`` arrays of shape
    ``(windows, longest, ·)``: inputs, outputs, loss weights (0 on the padding of shorter
    windows) and the outputs' saturation flags."""
    spans = training_windows(record, window)
    if not spans:
        raise ValueError("the record has no training rows")
    T = max(b - a for a, b in spans)
    B = len(spans)
    U = np.zeros((B, T, record.m))
    Y = np.zeros((B, T, record.p))
    W = np.zeros((B, T, record.p))
    S = np.zeros((B, T, record.p), dtype=np.int8)
    for i, (a, b) in enumerate(spans):
        U[i, :b - a], Y[i, :b - a], S[i, :b - a] = record.u[a:b], record.y[a:b], \
            record.sat[a:b]
        W[i, :b - a] = 1.0
    return U, Y, W, S


def _descend(r: dict[str, Any], q: dict[str, Any], x0: Any, idx: np.ndarray,
             dims: tuple[int, int, int], adam: Any) -> None:
    """One Adam step from the simulation loss's gradients ``r`` (the C BPTT's, with respect
    to the constrained weights ``q``, chained to the free ones by torch, and to the batch's
    initial states ``x0[idx]``)."""
    import torch

    n, m, p = dims
    grads = unpack(r["grad"], n, m, p)
    adam.zero_grad()
    keys = [k for k in q if q[k].requires_grad]
    torch.autograd.backward([q[k] for k in keys], [torch.from_numpy(grads[k]) for k in keys])
    g = np.zeros((x0.shape[0], n))
    g[idx] = r["grad_x0"]
    x0.grad = torch.from_numpy(g)
    adam.step()


def fit_candidate(record: Record, options: SimOptions | None = None,
                  progress: Callable[[int], None] | None = None,
                  init: dict[str, np.ndarray] | None = None) -> Candidate:
    """Fit one candidate (module docstring): Adam over :attr:`SimOptions.steps` steps, then
    L-BFGS over :attr:`SimOptions.polish` iterations (:mod:`controllers.identification.
    polish`), the best evaluation of both kept; ``progress`` is called with the number of
    steps and iterations done after each evaluation; ``init``: initial weights (default
    :func:`controllers.identification.training.init_params`)."""
    import torch

    from controllers.identification.training import init_params, trainable_params

    opt = options or SimOptions()
    single_threaded()
    torch.manual_seed(opt.seed)
    U, Y, W, S = window_arrays(record, opt.window)
    params = trainable_params(init or init_params(opt.n, record.m, record.p, opt.seed,
                                                  opt.bz_init),
                              opt.train_uz, 1.0 - opt.nu_margin, opt.sigma_z_max, opt.rho_max)
    x0 = torch.zeros(U.shape[0], opt.n, dtype=torch.float64, requires_grad=True)
    judge = _Judge(record, opt, progress)
    _adam(params, x0, (U, Y, W, S), opt, judge)
    if opt.polish > 0 and judge.best.params is not None:
        from controllers.identification.polish import polish

        stop = opt.steps + opt.polish

        def offer(it: int, qn: dict[str, np.ndarray]) -> bool:
            step = opt.steps + it
            if it % MIN_EVAL_EVERY and step != stop:
                return False
            judge(step, qn, None)
            return step - judge.best.step >= POLISH_PATIENCE

        polish((U, Y, W, S), judge.best.params, judge.best.x0, judge.effective, opt.train_uz,
               opt.polish, offer)
    best = judge.best
    chosen = best.params if best.params is not None else judge.last
    return Candidate(params=chosen, nu=nu_numpy(chosen), score=best.score,
                     best_step=best.step, steps_run=best.history[-1]["step"],
                     wall_time=time.perf_counter() - judge.t0, options=asdict(opt),
                     history=best.history)


def single_threaded() -> None:
    """One thread for torch and for the OpenBLAS libraries numpy and scipy loaded (Linux;
    elsewhere torch only): a candidate is one thread's work, and on a machine with as many
    busy workers as cores, OpenBLAS's idle threads slowed scipy's L-BFGS-B of the initial
    states 2-20-fold (measured with 2 workers on 2 cores)."""
    import ctypes

    import scipy.optimize  # noqa: F401  (loads scipy's OpenBLAS, which L-BFGS-B calls)
    import torch

    torch.set_num_threads(1)
    try:
        with open("/proc/self/maps", encoding="utf-8") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower()}
    except OSError:
        return
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("openblas_set_num_threads", "scipy_openblas_set_num_threads",
                     "openblas_set_num_threads64_", "scipy_openblas_set_num_threads64_"):
            setter = getattr(lib, name, None)
            if setter is not None:
                setter(1)
                break


def _adam(params: dict[str, Any], x0: Any, arrays: tuple[np.ndarray, ...], opt: SimOptions,
          judge: _Judge) -> None:
    """The Adam phase of :func:`fit_candidate`: :attr:`SimOptions.steps` steps, each on a
    batch of the windows ``arrays`` (``U, Y, W, S``), evaluated by ``judge`` every so often
    (early stop after :attr:`SimOptions.patience` epochs without a better score)."""
    import torch

    from controllers.identification.training import project

    U, Y, W, S = arrays
    B, n, m, p = U.shape[0], opt.n, U.shape[2], Y.shape[2]
    rng = np.random.default_rng(opt.seed)
    n_batches = min(STEPS_PER_EPOCH, B)
    steps, target = opt.steps, 1.0 - opt.nu_margin
    adam, scheduler = _optimiser([v for v in params.values() if v.requires_grad] + [x0], opt)
    patience = opt.patience * STEPS_PER_EPOCH
    every = opt.eval_every or max(MIN_EVAL_EVERY, steps // EVALUATIONS)
    batches: list[np.ndarray] = []
    for step in range(steps + 1):
        q = judge.effective(params)
        qn = {k: v.detach().numpy().copy() for k, v in q.items()}
        if step % every == 0 or step == steps:
            judge(step, qn, x0.detach().numpy())
            if patience and step - judge.best.step >= patience:
                break
        if step == steps:
            break
        if not batches:       # a new epoch: the windows in a new order, cut into batches
            batches = np.array_split(rng.permutation(B), n_batches)
        idx = batches.pop()
        w = W[idx]
        loss = SimLoss(U[idx], Y[idx], w / w.sum(), S[idx])
        _descend(loss(qn, x0.detach().numpy()[idx]), q, x0, idx, (n, m, p), adam)
        scheduler.step()
        project(params, target, opt.sigma_z_max, opt.rho_max)
        with torch.no_grad():
            x0.clamp_(-1.0, 1.0)


class _Judge:
    """The evaluations of one candidate: the validation free run of a set of weights
    (:func:`simulate`, warm started from the last estimates), the selection, the progress."""

    def __init__(self, record: Record, opt: SimOptions,
                 progress: Callable[[int], None] | None) -> None:
        self.record, self.opt, self.progress = record, opt, progress
        self.scored = _scored(record)
        self.starts: dict[int, np.ndarray] = {}
        self.best = _Selection()
        self.last: dict[str, np.ndarray] = {}
        self.t0 = time.perf_counter()

    def effective(self, params: dict[str, Any]) -> dict[str, Any]:
        """The weights the model runs: ``params`` through the δISS and contraction caps
        (:func:`controllers.identification.training.constrain`)."""
        from controllers.identification.training import constrain

        o = self.opt
        return constrain(params, 1.0 - o.nu_margin, o.sigma_z_max, o.rho_max)[0]

    def __call__(self, step: int, qn: dict[str, np.ndarray], x0: np.ndarray | None) -> None:
        """Score ``qn`` at ``step`` (``x0``: the training windows' initial states, kept with
        the best weights; ``None``: the best's are kept) and report the progress."""
        xi = simulate(qn, self.record, self.opt.x0_samples, self.starts)
        self.last = qn
        self.best.offer(step, qn, float(np.mean(rms(self.record, xi)[self.scored])),
                        time.perf_counter() - self.t0, x0)
        if self.progress is not None:
            self.progress(step)


def _optimiser(trainable: list[Any], opt: SimOptions) -> tuple[Any, Any]:
    """Adam over ``trainable`` with its learning rate decaying exponentially from ``lr`` to
    ``lr_final`` over the steps."""
    import torch

    adam = torch.optim.Adam(trainable, lr=opt.lr)
    gamma = (opt.lr_final / opt.lr) ** (1.0 / max(1, opt.steps - 1))
    return adam, torch.optim.lr_scheduler.ExponentialLR(adam, gamma)


@dataclass
class _Selection:
    """Model selection: the best weights so far by validation score (ν < 1 only) and every
    evaluation's record."""

    params: dict[str, np.ndarray] | None = None
    score: float = math.inf
    step: int = -1
    history: list[dict[str, Any]] = field(default_factory=list)
    #: the training windows' initial states with the best weights
    x0: np.ndarray | None = None

    def offer(self, step: int, qn: dict[str, np.ndarray], score: float, t: float,
              x0: np.ndarray | None = None) -> None:
        """Record the evaluation at ``step`` and keep ``qn`` (and ``x0``, when given) when it
        is the best yet."""
        self.history.append({"step": step, "score": score, "time": t})
        if math.isfinite(score) and score < self.score and nu_numpy(qn) < 1.0:
            self.params, self.score, self.step = qn, score, step
            if x0 is not None:
                self.x0 = np.array(x0, dtype=float)
