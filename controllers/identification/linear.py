"""The linear baseline: an ARX model fitted on the same training rows, scored the same way.

Whether a neural model is worth it shows against the simplest model that could do the job.
``cosim train`` fits, in the same run, the multi-input multi-output ARX model

    y_t = c + Σ_{i=1..na} A_i y_{t−i} + Σ_{i=0..nb−1} B_i u_{t−nk−i}

by least squares on the training rows (regressors never reaching into another experiment),
for every order ``na ∈ 1..4``, ``nb ∈ 1..4``, delay ``nk ∈ {0, 1}``, and keeps the orders whose
free-run simulation has the lowest validation RMS (training RMS without validation rows). Its
free run starts each experiment from its first ``max(na, nb + nk − 1)`` measured samples (the
ARX model's initial state), then uses its own outputs; it is read through the sensor limits
as the GRU is (:mod:`controllers.identification.saturation`). A simulation that diverges
scores infinity.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from controllers.identification.record import Record

__all__ = ["ORDERS", "ARXModel", "fit_arx"]

#: The orders tried: ``na``, ``nb``, ``nk``, the simplest first (``na + nb``).
ORDERS = tuple(sorted(itertools.product(range(1, 5), range(1, 5), (0, 1)),
                      key=lambda o: (o[0] + o[1], o[0], o[2])))
#: A more complex order replaces a simpler one only when its RMS is lower by this share.
IMPROVEMENT = 1e-6


@dataclass(frozen=True)
class ARXModel:
    """An ARX model in normalised units: ``theta`` holds, per output (column), the
    coefficients of ``[1, y_{t−1} … y_{t−na}, u_{t−nk} … u_{t−nk−nb+1}]`` (each lag all
    outputs or all inputs)."""

    na: int
    nb: int
    nk: int
    theta: np.ndarray

    @property
    def lag(self) -> int:
        """Samples of an experiment that start its simulation."""
        return max(self.na, self.nb + self.nk - 1, 1)

    def simulate(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Free run (T, p) over one experiment's inputs ``u``, its first :attr:`lag` outputs
        taken from the measured ``y``."""
        T = len(u)
        out = np.array(y, dtype=float, copy=True)
        L = min(self.lag, T)
        with np.errstate(over="ignore", invalid="ignore"):
            for t in range(L, T):
                out[t] = _regressor(out, u, t, self.na, self.nb, self.nk) @ self.theta
                if not np.all(np.isfinite(out[t])) or np.max(np.abs(out[t])) > 1e6:
                    out[t:] = np.inf
                    break
        return out


def _regressor(y: np.ndarray, u: np.ndarray, t: int, na: int, nb: int, nk: int) -> np.ndarray:
    parts = [np.ones(1)]
    parts += [y[t - i] for i in range(1, na + 1)]
    parts += [u[t - nk - i] if t - nk - i >= 0 else np.zeros(u.shape[1]) for i in range(nb)]
    return np.concatenate(parts)


def _least_squares(record: Record, na: int, nb: int, nk: int) -> np.ndarray | None:
    lag = max(na, nb + nk - 1, 1)
    rows, targets = [], []
    for a, b in record.experiments():
        u, y, split = record.u[a:b], record.y[a:b], record.split[a:b]
        for t in range(lag, b - a):
            if split[t] == "train":
                rows.append(_regressor(y, u, t, na, nb, nk))
                targets.append(y[t])
    if len(rows) <= len(rows[0]) if rows else True:
        return None
    X, Y = np.array(rows), np.array(targets)
    theta, *_ = np.linalg.lstsq(X, Y, rcond=None)
    return theta


def simulate(model: ARXModel, record: Record) -> np.ndarray:
    """The ARX model's free run over every experiment of the record, read through the
    sensor limits."""
    xi = np.empty_like(record.y)
    for a, b in record.experiments():
        xi[a:b] = model.simulate(record.u[a:b], record.y[a:b])
    return record.limits.clip(xi)


def fit_arx(record: Record) -> ARXModel | None:
    """The ARX model of the orders (:data:`ORDERS`) with the lowest validation (else
    training) simulation RMS, averaged over the outputs (a simpler one when a more complex one
    is not better by :data:`IMPROVEMENT`); ``None`` when the training rows are too few for
    any."""
    scored = record.split == ("val" if record.has("val") else "train")
    best, best_score = None, math.inf
    for na, nb, nk in ORDERS:
        theta = _least_squares(record, na, nb, nk)
        if theta is None:
            continue
        model = ARXModel(na, nb, nk, theta)
        xi = simulate(model, record)
        err = record.y[scored] - xi[scored]
        score = float(np.mean(np.sqrt(np.mean(err ** 2, axis=0))))
        if math.isfinite(score) and score < best_score * (1.0 - IMPROVEMENT) - 1e-12:
            best, best_score = model, score
    return best
