"""Measured disturbances: the GRU conditioned on a held disturbance, and the static
feedforward it gives.

A model trained with measured disturbances takes ``v = (u, d)`` (``eq:gru`` with ``m_u``
manipulated inputs then ``q`` disturbances, normalised). The input enters the GRU only
through ``W_z v``, ``W_r v`` and ``W_h v``, so with ``d`` held at a value ``d̄``::

    W v + b = W_u u + (b + W_d d̄)

the model is a GRU of the manipulated inputs alone whose biases carry the disturbance
(:func:`condition`). Every design made for a GRU (equilibria, set-points, the FHOCP, PI
tuning) then applies to the conditioned model unchanged; :class:`BiasShift` moves the biases
of a conditioned model in place when the measured disturbance changes, so that what was
built on them (an FHOCP, its kernel workspaces) follows.

The δISS certificate (``th:stability-bonassi``) of the full model over its whole input box
covers every conditioned one: each row of ``[W_u  U  b + W_d d̄]`` has an ∞-norm no larger
than the same row of ``[W_u  W_d  U  b]`` when ``‖d̄‖∞ ≤ 1`` (the disturbance inside its
box), so the gate bounds of :mod:`controllers.certification.bounds` only shrink (docs:
design/disturbances.md).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

__all__ = ["BiasShift", "condition", "feedforward_gain", "held_error", "input_gain", "nominal",
           "rates"]

#: The input weights and the biases they shift.
_GATES = (("W_z", "b_z"), ("W_r", "b_r"), ("W_h", "b_h"))


def nominal(model: Any) -> np.ndarray:
    """The disturbances' nominal value, normalised: ``0`` (the middle of each box, or the
    normalisation's offset)."""
    return np.zeros(model.q)


def condition(model: Any, d: np.ndarray | None = None) -> Any:
    """The model of the manipulated inputs alone with the disturbances held at ``d``
    (normalised; default :func:`nominal`): the module docstring.

    A model without disturbances is returned as it is. The result has its own bias arrays
    (:class:`BiasShift` moves them) and shares the weights with ``model``.
    """
    q = model.q
    if not q:
        return model
    m_u = model.m - q
    d = nominal(model) if d is None else np.asarray(d, dtype=float).reshape(q)
    params = dict(model.params)
    for w, b in _GATES:
        W = np.asarray(model.params[w], dtype=float)
        params[w] = W[:, :m_u]
        params[b] = np.asarray(model.params[b], dtype=float) + W[:, m_u:] @ d
    problem = replace(model.problem, disturbances=())
    return replace(model, params=params, u_offset=np.asarray(model.u_offset)[:m_u],
                   u_scale=np.asarray(model.u_scale)[:m_u],
                   input_names=list(model.input_names)[:m_u],
                   input_units=list(model.input_units)[:m_u], problem=problem,
                   certificate=None, held_from=model)


class BiasShift:
    """Moves the biases of a conditioned model's parameters (``params``, shared by what was
    built on them) to a new held disturbance, in place.

    Parameters
    ----------
    model : GRUModel
        The full model (inputs and disturbances).
    params : dict of ndarray
        The conditioned model's parameters (:func:`condition`), whose ``b_z b_r b_h`` arrays
        are overwritten.
    """

    def __init__(self, model: Any, params: dict[str, np.ndarray]) -> None:
        self.q = model.q
        m_u = model.m - self.q
        self._base = {b: np.asarray(model.params[b], dtype=float).copy() for _, b in _GATES}
        self._W = {b: np.asarray(model.params[w], dtype=float)[:, m_u:] for w, b in _GATES}
        self.params = params
        self.d = np.full(self.q, np.nan)
        #: ``(Δb_z, Δb_r, Δb_h)`` (3n): the shift from the full model's biases
        self.delta = np.zeros(3 * params["b_z"].shape[0])

    def set(self, d: np.ndarray) -> bool:
        """Hold the disturbances at ``d`` (normalised); ``True`` when the biases changed."""
        d = np.asarray(d, dtype=float).reshape(self.q)
        if np.array_equal(d, self.d):
            return False
        n = self.delta.size // 3
        for k, (b, W) in enumerate(self._W.items()):
            # Σ_j W_:j d_j from j = 0 on, as the exported controller sums it (controller.c
            # hold): the same shift to the bit, whatever BLAS a matrix product would call
            acc = np.zeros(n)
            for j in range(self.q):
                acc = acc + W[:, j] * d[j]
            self.delta[k * n:(k + 1) * n] = acc
            np.add(self._base[b], acc, out=self.params[b])
        self.d = d.copy()
        return True


def feedforward_gain(model: Any, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The static feedforward ``Δu = K_ff Δd`` that keeps the outputs where they are when
    the disturbances move, from the model's steady-state gains at the equilibrium ``(x, u)``
    (normalised; ``u`` the model's full input ``(u, d)``): ``K_ff = −G_u⁺ G_d`` with
    ``G = U_o (I − ∂f/∂x)⁻¹ ∂f/∂v`` split into its input and disturbance columns (the
    least-squares inverse when the plant is not square)."""
    from controllers.equilibrium import jacobians

    params = {k: np.asarray(v, dtype=float) for k, v in model.params.items()}
    A, B = jacobians(params, np.asarray(x, dtype=float), np.asarray(u, dtype=float))
    G = params["U_o"] @ np.linalg.solve(np.eye(A.shape[0]) - A, B)
    m_u = model.m - model.q
    return -np.linalg.pinv(G[:, :m_u]) @ G[:, m_u:]


def input_gain(model: Any) -> float:
    """``γ_d``: how far one step of the full model moves apart (∞-norm) for disturbances
    ``‖Δd‖∞`` apart, per unit, on ``‖x‖∞ ≤ 1`` (lem:held-disturbance, docs:
    design/disturbances.md)::

        γ_d = ‖W_h,d‖∞ + ¼ ‖U_h‖∞ ‖W_r,d‖∞ + ¼ (1 + φ̄_h) ‖W_z,d‖∞

    the input terms of the same increment bound as ν's (``th:stability-bonassi``), with the
    candidate's factor ``1 − z ≤ 1``."""
    from controllers.certification.bounds import gate_bounds, inf_norm

    P = {k: np.asarray(v, dtype=float) for k, v in model.params.items()}
    m_u = model.m - model.q
    _, _, phi_h = gate_bounds(P)
    return (inf_norm(P["W_h"][:, m_u:]) + 0.25 * inf_norm(P["U_h"]) * inf_norm(P["W_r"][:, m_u:])
            + 0.25 * (1.0 + phi_h) * inf_norm(P["W_z"][:, m_u:]))


def rates(model: Any) -> np.ndarray:
    """The largest change per sample of each disturbance, normalised: the problem's
    ``rate``, else the identification data's (the model file's ``training``
    ``disturbance_rates``), else the whole box (any change in one sample)."""
    data = (model.training or {}).get("disturbance_rates") or {}
    out = []
    for c in model.problem.disturbances:
        rate = c.rate if c.rate is not None else data.get(c.name)
        width = c.max - c.min
        rate = width if rate is None or not np.isfinite(rate) else min(float(rate), width)
        out.append(rate / abs(c.scale))
    return np.array(out)


def held_error(model: Any, rho_s: float, N: int, K: int = 0) -> np.ndarray:
    """``e_d(i)``, ``i = 0 … N`` steps after the estimate: a bound of ``‖x_i − x̃_i‖∞``
    between the model run as the controller predicts (over the inputs' dead time ``K`` each
    disturbance as the model sees it, ``d_{k+i−L}``, while known, then the FHOCP's stages
    with it held at ``d_k``) and with the real values, when each moves at most its
    :func:`rates` per sample (lem:held-disturbance)::

        e_d(0) = 0,   e_d(i + 1) = ρ_s e_d(i) + γ_d δ_i,   δ_i = min(s_i δ, Δ)
        s_i = max(0, i − L_min)                       (i < K: the prediction)
        s_i = max(i − L_min, L_max − i, 0)            (i ≥ K: the FHOCP, d_k = d̃_L held)

    ``δ`` the largest normalised rate, ``Δ`` the largest normalised box width (2 with the
    default normalisation), ``L`` the disturbances' dead times (the model sees
    ``d_{k+i−L}``). A disturbance known ahead (``preview = true``) is held at
    ``d̃_{max(K, L)}``, nearer the real values at every stage ``i ≥ K``: the bound covers it
    as it is. Infinite from ``i = 1`` on when ``ρ_s ≥ 1`` and the disturbances can move."""
    problem = model.problem
    delta = float(np.max(rates(model), initial=0.0))
    width = float(max((c.max - c.min) / abs(c.scale) for c in problem.disturbances))
    lag = min(c.delay for c in problem.disturbances)
    lag_max = max(c.delay for c in problem.disturbances)
    gamma = input_gain(model)
    e = np.zeros(N + 1)
    for i in range(N):
        steps = max(0, i - lag) if i < K else max(i - lag, lag_max - i, 0)
        step = min(steps * delta, width)
        e[i + 1] = rho_s * e[i] + gamma * step if np.isfinite(rho_s) else np.inf
    if rho_s >= 1 and np.any(e > 0):
        e[np.argmax(e > 0):] = np.inf
    return e
