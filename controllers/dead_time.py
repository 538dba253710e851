"""Dead time: what the model sees of a signal declared with ``delay = K`` samples.

A problem's input or measured disturbance with a dead time of ``K`` samples acts on the
outputs ``K`` samples late: the GRU (``eq:gru``) is trained and run on the *model input*
``v_k = (u_{k−K_1}, …, d_{k−L_1}, …)`` rather than on the signals themselves
(:attr:`controllers.problem.ControlProblem.delays`). The GRU then needs no dead time of its own,
and the controller, which knows the inputs it applied, predicts the first ``K`` samples of
its horizon from them (docs: design/disturbances.md).

:func:`delayed` shifts a record's columns (identification); :class:`DelayLine` holds the last
``max K`` values of every signal at run time (the observer's and the prediction's past inputs).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["DelayLine", "delayed", "input_delay"]


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
    """The manipulated inputs' common dead time ``K`` [samples] (0 without a problem): the
    steps the robust MPC predicts before its decisions act, the shift of its tightening.

    Raises
    ------
    DesignError
        The inputs have different dead times (one line naming them).
    """
    if problem is None:
        return 0
    delays = {c.name: c.delay for c in problem.inputs}
    if len(set(delays.values())) > 1:
        from controllers.errors import DesignError

        raise DesignError("the inputs have different dead times ("
                          + ", ".join(f"{n} {k}" for n, k in delays.items())
                          + " samples); the robust MPC takes one dead time for all inputs")
    return next(iter(delays.values()), 0)


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
