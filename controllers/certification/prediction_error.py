"""The model's measured prediction error over a horizon: the tightening of the uncertified mode
(and the paper's ``w̄_y``, the largest output error on the test data: :func:`w_y_bar_from_data`).

The theorem (``th:feasibility-stability``) tightens the output constraints by bounds that hold
for every plant within ``w̄_y`` of the model: ``w_L`` (the largest output error, kept over
the whole horizon) plus the observer-error terms ``a_i ê_o + b_i``. When its hypotheses fail
the robust MPC still runs (the uncertified mode of :mod:`cosim.adapters.robust_mpc`), with a
tightening measured instead of proved: how far the outputs of held-back data came from what
the controller would have predicted.

The tracking law predicts the output ``i`` steps ahead as the model's free run plus the
filtered output mismatch ``d̂`` (``d̂_k = d̂_{k−1} + β (r_k − d̂_{k−1})``, ``r = y − ξ``; its
observer has zero gains, so its state estimate is the model's free run under the applied
inputs). On the held-back rows (validation and test) of the identification record, with the
model's free run ``ξ`` of :mod:`controllers.identification.simulation`:

    B_j(i) = q_{95 %} over k of |r_{k+i, j} − d̂_{k, j}|,   k, k + i held-back rows of one
                                                         experiment

made non-decreasing in ``i`` (a prediction further ahead is never assumed better). With
measured disturbances the controller's prediction holds them at their value at ``k`` over its
horizon (:mod:`controllers.disturbances`): ``ξ_{k+i}`` is then the prediction from the free
run's state at ``k`` with the applied inputs and the disturbances held
(:func:`held_predictions`), so that ``B`` covers what holding them costs, measured. The 95th
percentile (:data:`QUANTILE`), not the largest error: the largest comes from the fastest
transients of the identification data (input steps across the whole box), which a controller
near a constraint does not make, and taken whole it swallows a fifth of a quickly trained
model's box. Measured on the example CSTR after 150 epochs (docs: guide/certificates.md,
"Uncertified mode"): the largest error 0.165 mol/L of its 0.9 mol/L box in CA, 0.08 at the
99th percentile, 0.05 at the 95th; on its set-point scenario the 95th tracks every set-point
with no violation (0.73x the PI's IAE), the 99th leaves offsets of 1.5 % of the box at the
two set-points near the top, the largest of 11 %. The
uncertified mode tightens output row ``j`` at step ``i`` by ``Σ_k |L_jk| B_k(i)`` around
``y + d̂``. ``d̂`` runs from each experiment's first row, so that it has settled by the
held-back rows as it has in a running controller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.errors import DataError

__all__ = ["BETA_MIN", "HORIZON", "QUANTILE", "OffsetFilter", "error_profile",
           "held_predictions", "margins", "offset_filter", "w_y_bar_from_data"]

#: Steps ahead measured (beyond, the last value holds).
HORIZON = 200
#: The quantile of the held-back errors taken as the tightening (1: the largest).
QUANTILE = 0.95
#: The smallest offset filter :func:`offset_filter` gives (the paper law's default).
BETA_MIN = 0.05


@dataclass(frozen=True)
class OffsetFilter:
    """The offset filter measured on a model's residual (:func:`offset_filter`): ``beta``,
    and per output the sensor noise's and the mismatch's per-sample standard deviations
    (normalised)."""

    beta: float
    noise: np.ndarray
    drift: np.ndarray


def offset_filter(y: np.ndarray, xi: np.ndarray, spans: list[tuple[int, int]]
                  ) -> OffsetFilter | None:
    """The offset filter ``β`` of the tracking law's ``d̂ ← d̂ + β (y − ŷ − d̂)`` measured on
    the residual ``r = y − ξ`` of the model's free run ``xi`` over ``spans`` (row ranges
    ``(start, end)`` of consecutive rows, such as :meth:`Record.experiments
    <controllers.identification.record.Record.experiments>` or ``stretches``; the
    differences never cross from one to the next; ``None`` when no span has three rows).

    ``d̂`` estimates an output disturbance that the law assumes constant over its horizon:
    a random walk ``d_k = d_{k−1} + w_k`` (variance ``q`` a sample) seen through white sensor
    noise ``v_k`` (variance ``ρ``), ``r_k = d_k + v_k``. Then ``Δr_k = w_k + v_k − v_{k−1}``:
    ``E[Δr_k²] = q + 2ρ`` and ``E[Δr_k Δr_{k−1}] = −ρ``, which give ``ρ`` and ``q`` by their
    sample moments (``ρ ≥ 0``; a mismatch that drifts smoothly, as a model's error on
    noise-free data, has a positive lag-one covariance and ``ρ = 0``), and the filter's
    steady-state Kalman gain ``β = 2 / (1 + √(1 + 4ρ/q))``: 1 without noise, the whole error
    taken each sample; smaller where the noise is larger than the mismatch's motion. One
    ``β`` for every output: the smallest, at least :data:`BETA_MIN`."""
    r = np.asarray(y, dtype=float) - np.asarray(xi, dtype=float)
    d0, d1 = [], []
    for a, b in spans:
        dr = np.diff(r[a:b], axis=0)
        if len(dr) >= 2:
            d0.append(dr[1:] * dr[1:])
            d1.append(dr[1:] * dr[:-1])
    if not d0:
        return None
    c0, c1 = np.mean(np.concatenate(d0), axis=0), np.mean(np.concatenate(d1), axis=0)
    noise = np.maximum(-c1, 0.0)
    drift = np.maximum(c0 - 2.0 * noise, 0.0)
    ratio = np.divide(noise, drift, out=np.full_like(noise, np.inf), where=drift > 0)
    ratio[noise == 0] = 0.0
    beta = float(np.min(2.0 / (1.0 + np.sqrt(1.0 + 4.0 * ratio))))
    return OffsetFilter(max(beta, BETA_MIN), np.sqrt(noise), np.sqrt(drift))



def held_predictions(params: dict[str, np.ndarray], u: np.ndarray, x: np.ndarray, q: int,
                     experiments: list[tuple[int, int]], horizon: int = HORIZON
                     ) -> np.ndarray:
    """``(H + 1, T, p)``: the output predicted ``i`` steps ahead of each row ``k`` from the
    free run's state ``x[k]`` with the inputs ``u`` (normalised, ``T × m``) as applied and
    their last ``q`` columns (the measured disturbances) held at row ``k``'s; rows past the
    experiment's end repeat its last prediction."""
    from controllers import gru

    T, p = len(u), params["U_o"].shape[0]
    out = np.empty((horizon + 1, T, p))
    # eq:gru on every row at once: the states as columns, the biases as column vectors
    cols = {**params, **{b: np.asarray(params[b])[:, None] for b in ("b_z", "b_r", "b_h",
                                                                      "b_o")}}
    for a, b in experiments:
        X = np.array(x[a:b], dtype=float).T
        held = u[a:b, u.shape[1] - q:]
        for i in range(horizon + 1):
            out[i, a:b] = gru.output(cols, X).T
            if i == horizon:
                break
            V = u[np.minimum(np.arange(a, b) + i, b - 1)].copy()
            V[:, V.shape[1] - q:] = held
            X = gru.step(cols, X, V.T)
    return out


def error_profile(y: np.ndarray, xi: np.ndarray, held_back: np.ndarray,
                  experiments: list[tuple[int, int]], beta: float,
                  horizon: int = HORIZON, quantile: float = QUANTILE,
                  ahead: np.ndarray | None = None) -> np.ndarray | None:
    """``B(i)`` (``(H + 1, p)``, normalised; module docstring) from the measured outputs
    ``y`` and the model's free run ``xi`` (T, p), the held-back rows (a boolean mask) and
    the experiments' row ranges, at the ``quantile`` of the errors (1: their largest);
    ``None`` when no experiment has two held-back rows. ``ahead``: the predictions with the
    disturbances held (:func:`held_predictions`), instead of the free run ``i`` rows on."""
    y, xi = np.asarray(y, dtype=float), np.asarray(xi, dtype=float)
    held_back = np.asarray(held_back, dtype=bool)
    p = y.shape[1]
    errors: list[list[np.ndarray]] = [[] for _ in range(horizon + 1)]
    for a, b in experiments:
        r = y[a:b] - xi[a:b]
        d = np.zeros_like(r)
        acc = np.zeros(p)
        for k in range(b - a):
            acc = acc + beta * (r[k] - acc)
            d[k] = acc
        rows = np.flatnonzero(held_back[a:b])
        if rows.size < 2:
            continue
        inside = np.zeros(b - a, dtype=bool)
        inside[rows] = True
        for i in range(min(horizon, b - a - 1) + 1):
            k = np.flatnonzero(inside[: b - a - i] & inside[i:])
            if k.size:
                pred = r[k + i] if ahead is None else y[a + k + i] - ahead[i, a + k]
                errors[i].append(np.abs(pred - d[k]))
    steps = [i for i in range(horizon + 1) if errors[i]]
    if not steps or steps[0] != 0:
        return None
    last = next((i for i in range(horizon + 1) if not errors[i]), horizon + 1)
    bound = np.array([np.quantile(np.concatenate(errors[i]), quantile, axis=0)
                      for i in range(last)]).reshape(last, p)
    return np.maximum.accumulate(bound, axis=0)


def margins(profile: Any, L: np.ndarray, N: int, shift: int = 0) -> np.ndarray:
    """The tightening of the constraint rows ``L y ≤ h`` at steps ``0 … N`` (``(N + 1, q)``):
    ``Σ_k |L_jk| B_k(min(i + shift, H))``; ``shift``: the inputs' dead time, the steps the
    prediction runs before the FHOCP's first stage."""
    B = np.asarray(profile, dtype=float)
    idx = np.minimum(np.arange(N + 1) + int(shift), B.shape[0] - 1)
    return B[idx] @ np.abs(np.asarray(L, dtype=float)).T


def w_y_bar_from_data(model: Any, u: np.ndarray, y: np.ndarray, split: np.ndarray,
                      test: str = "test", washout: str | None = "val") -> float:
    """``w̄_y``: the largest absolute output error of the model on the test data, normalised.

    The model is simulated open loop (``eq:gru``) on the data's inputs; the error
    ``y_k − ξ_k`` is measured on the rows of the ``test`` split (paper section V: "maximum
    absolute value of the prediction error on the test dataset in the normalized
    variables"). The simulation starts at the model equilibrium for the first measured output
    of the ``washout`` split (the rows just before the test split, default validation), so
    that the initial state is forgotten (δISS) before the test rows begin; ``washout=None``
    starts at the first test row.

    Parameters
    ----------
    model : GRUModel
    u, y : (T, m), (T, p) arrays
        Inputs and outputs in physical units, in the model's signal order.
    split : (T,) array of str
        The split of each row (``"train"``, ``"val"``, ``"test"``).

    Raises
    ------
    DataError
        No rows in the ``test`` split.
    """
    from controllers.equilibrium import equilibrium_for_output
    from controllers.gru import simulate

    split = np.asarray(split)
    keep = split == test
    if not np.any(keep):
        raise DataError(f"no rows in split {test!r}")
    idx = np.flatnonzero(keep)
    start = idx[0]
    if washout is not None and np.any(split == washout):
        w_idx = np.flatnonzero(split == washout)
        if w_idx[-1] == start - 1:  # contiguous, just before the test rows
            start = w_idx[0]
    stop = idx[-1] + 1
    u_n = model.normalize_u(np.asarray(u, dtype=float)[start:stop])
    y_n = model.normalize_y(np.asarray(y, dtype=float)[start:stop])
    x0, _ = equilibrium_for_output(model.params, y_n[0])
    _, xi = simulate(model.params, x0, u_n)
    mask = keep[start:stop]
    return float(np.max(np.abs(y_n[mask] - xi[mask])))
