"""Dead time: what the model sees of a signal declared with ``delay = K`` samples.

A problem's input or measured disturbance with a dead time of ``K`` samples acts on the
outputs ``K`` samples late: the GRU (``eq:gru``) is trained and run on the *model input*
``v_k = (u_{k−K_1}, …, d_{k−L_1}, …)`` rather than on the signals themselves
(:attr:`controllers.problem.ControlProblem.delays`). The GRU then needs no dead time of its own,
and the controller, which knows the inputs it applied, predicts the first ``K = min K_j``
samples of its horizon from them; an input ``j`` whose dead time is ``e_j = K_j − K`` samples
longer has its first ``e_j`` FHOCP inputs already applied: they are fixed
(:class:`InputPrefix`), and the input it applies now is its FHOCP input ``e_j`` (docs:
design/disturbances.md).

:func:`delayed` shifts a record's columns (identification); :class:`DelayLine` holds the last
``max K`` values of every signal at run time (the observer's and the prediction's past inputs).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["DelayLine", "InputPrefix", "delayed", "input_delay", "input_lags"]


def delayed(u: np.ndarray, delays: Sequence[int], experiment: np.ndarray | None = None
            ) -> np.ndarray:
    """The model inputs of a record: column ``j`` of ``u`` shifted down by ``delays[j]`` rows
    within each experiment.

    The first ``delays[j]`` rows of an experiment take its first value (the signal is
    assumed to have been there before the record began, as at rest); no row is dropped, so
    the result stays aligned with the outputs, the split and the experiments.

    Parameters
    ----------
    u : (T, m) array
    delays : sequence of int
        One per column, ``≥ 0``.
    experiment : (T,) array, optional
        The experiment of each row (consecutive rows); default: one experiment.
    """
    u = np.asarray(u, dtype=float)
    delays = [int(k) for k in delays]
    if len(delays) != u.shape[1] or min(delays, default=0) < 0:
        raise ValueError(f"{len(delays)} delays (each >= 0) for {u.shape[1]} columns")
    if not any(delays):
        return u.copy()
    e = np.zeros(len(u), dtype=int) if experiment is None else np.asarray(experiment)
    cuts = [0, *(np.flatnonzero(e[1:] != e[:-1]) + 1).tolist(), len(u)]
    v = np.empty_like(u)
    for start, end in itertools.pairwise(cuts):
        for j, k in enumerate(delays):
            k = min(k, end - start)
            v[start:start + k, j] = u[start, j]
            v[start + k:end, j] = u[start:end - k, j]
    return v


def input_delay(problem: Any) -> int:
    """The manipulated inputs' shortest dead time ``K = min K_j`` [samples] (0 without a
    problem): the steps the robust MPC predicts before its decisions act, the shift of its
    tightening."""
    if problem is None or not problem.inputs:
        return 0
    return min(c.delay for c in problem.inputs)


def input_lags(problem: Any) -> tuple[int, ...]:
    """Each manipulated input's dead time beyond the shortest, ``e_j = K_j − K`` [samples]:
    how many of its first FHOCP inputs were already applied (:class:`InputPrefix`); ``()``
    without a problem."""
    if problem is None:
        return ()
    k = input_delay(problem)
    return tuple(c.delay - k for c in problem.inputs)


class InputPrefix:
    """The FHOCP inputs already applied when the inputs' dead times differ (module
    docstring): stage ``i`` of input ``j`` is fixed for ``i < e_j`` (``lags``), to the input
    applied ``e_j − i`` samples ago; the input applied now is stage ``e_j``.

    Without lags (every dead time the same) nothing is fixed and the input applied is stage
    0: :meth:`impose` returns its argument, :meth:`applied` its first row.

    Parameters
    ----------
    lags : sequence of int
        ``e_j`` per input (:func:`input_lags`), each below the horizon's free stages.
    """

    def __init__(self, lags: Sequence[int]) -> None:
        self.lags = np.array([int(e) for e in lags], dtype=int)
        if self.lags.size and self.lags.min() < 0:
            raise ValueError("lags must be >= 0")
        self.depth = int(self.lags.max(initial=0))
        #: ``values[i, j]``: stage ``i`` of input ``j`` (meaningful for ``i < e_j``)
        self.values = np.zeros((self.depth, self.lags.size))
        self.mask = np.arange(self.depth)[:, None] < self.lags[None, :]

    def set(self, past: np.ndarray) -> None:
        """The inputs applied before now, ``past`` (oldest first, at least ``depth`` rows,
        normalised): stage ``i`` of input ``j`` is ``past[−e_j + i]``."""
        if not self.depth:
            return
        past = np.asarray(past, dtype=float)
        rows = past.shape[0] - self.lags[None, :] + np.arange(self.depth)[:, None]
        cols = np.broadcast_to(np.arange(self.lags.size), rows.shape)
        self.values = np.where(self.mask, past[np.minimum(rows, past.shape[0] - 1), cols], 0.0)

    def impose(self, u: np.ndarray) -> np.ndarray:
        """``u`` (N, m) with its fixed stages set (a copy; ``u`` itself without lags)."""
        if not self.depth:
            return u
        out = np.array(u, dtype=float)
        head = out[: self.depth]
        head[self.mask] = self.values[self.mask]
        return out

    def bound(self, lbx: np.ndarray, ubx: np.ndarray, iu: np.ndarray) -> None:
        """Fix the stages in the solver's bounds ``lbx``, ``ubx`` (``iu``: the inputs'
        indices in ``w``, (N, m))."""
        if self.depth:
            idx = iu[: self.depth][self.mask]
            lbx[idx] = ubx[idx] = self.values[self.mask]

    def applied(self, u: np.ndarray) -> np.ndarray:
        """The inputs applied now from the plan ``u`` (N, m): stage ``e_j`` of input ``j``."""
        u = np.asarray(u, dtype=float)
        if not self.depth:
            return u[0].copy()
        return u[self.lags, np.arange(self.lags.size)].copy()


class DelayLine:
    """The last values of every signal, so that the model input ``v_k`` (``delays`` samples
    late) and the ones still to come are known at run time.

    ``push(s_k)`` records the signals of sample ``k``; :meth:`current` is ``v_k``;
    :meth:`ahead` ``(i)`` is ``v_{k+i}`` for ``i ≤ min(delays)``, known from the signals
    already pushed. Before the first push every past value is the first pushed one (at
    rest).
    """

    def __init__(self, delays: Sequence[int]) -> None:
        self.delays = np.array([int(k) for k in delays], dtype=int)
        if self.delays.size and self.delays.min() < 0:
            raise ValueError("delays must be >= 0")
        self.depth = int(self.delays.max(initial=0))
        self._buf: np.ndarray | None = None    # (depth + 1, m): row 0 the newest

    def reset(self) -> None:
        self._buf = None

    def push(self, s: np.ndarray) -> None:
        """Record the signals of the current sample (the newest)."""
        s = np.asarray(s, dtype=float)
        if self._buf is None:
            self._buf = np.tile(s, (self.depth + 1, 1))
            return
        self._buf[1:] = self._buf[:-1]
        self._buf[0] = s

    def current(self) -> np.ndarray:
        """``v_k``: signal ``j`` as it was ``delays[j]`` samples ago."""
        return self.ahead(0)

    def ahead(self, i: int) -> np.ndarray:
        """``v_{k+i}`` for ``i ≤ min(delays)``: signal ``j`` as it was ``delays[j] − i``
        samples ago (``i = 0``: :meth:`current`)."""
        if self._buf is None:
            raise RuntimeError("DelayLine.ahead before the first push")
        rows = self.delays - int(i)
        if rows.size and rows.min() < 0:
            raise ValueError(f"{i} samples ahead is past the shortest delay")
        return self._buf[rows, np.arange(self.delays.size)].copy()
