"""Bounds of the theory, from the GRU weights alone: δISS, observer and tightening scalars.

Pure functions of the weights (``eq:gru``) and of design numbers, in the model's NORMALISED
units, under the paper's names: the gate bounds σ̄_z, σ̄_r, φ̄_h and the δISS index ν
(``th:stability-bonassi``, ``eq:condition-deltaiss-gru``), ρ_s and c_s (``lem:Vs``), the
observer's ν_o, ρ_o, c_o, κ, L_max (``lem:Vo``), w_L (``eq:optimization``), the tightening
coefficients a_i, b_i (``eq:constraint_tightening_parameters``), ê_o,k and ē_∞
(``eq:eo-evolution``) and the terminal weight s (``eq:definition_s``).
:mod:`controllers.certification.certificates` assembles them into a
:class:`~controllers.certification.certificates.
Certificate`.

Norms. ``‖M‖∞`` of a matrix is the induced ∞-norm, the largest row sum of absolute values.
The paper writes ``‖(L U_o)_(j*)‖∞`` for a ROW: the proof of ``lem:Vs`` uses it as the gain
of ``(L U_o)_(j*) Δx ≤ ‖(L U_o)_(j*)‖∞ ‖Δx‖∞``, which holds for the induced norm of the
1×n matrix, i.e. the sum of absolute values of the row; that is what ``c_s``, ``c_o`` and the
denominator of ``alpha`` use here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from controllers.errors import CertificateError

__all__ = ["L_max", "c_o", "c_s", "check_gates", "contraction", "e_inf", "e_o_sequence",
           "gate_bounds", "inf_norm", "kappa", "nu", "nu_o", "rho_o", "rho_s", "row_norms",
           "terminal_weight", "tightening_parameters", "w_L"]


# --------------------------------------------------------------------------------------
# Norms and the δISS condition (th:stability-bonassi, lem:Vs)
# --------------------------------------------------------------------------------------
def inf_norm(M: Any) -> float:
    """Induced ∞-norm ``‖M‖∞``: the largest row sum of absolute values.

    A 1-D array is treated as a single ROW (its norm is the sum of absolute values), which
    is the meaning of ``‖(L U_o)_(j*)‖∞`` in ``lem:Vs``.
    """
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.size == 0:
        return 0.0
    return float(np.max(np.sum(np.abs(M), axis=1)))


def row_norms(M: Any) -> np.ndarray:
    """``‖M_(j*)‖∞`` for every row ``j`` (row sums of absolute values), as in ``lem:Vs``."""
    return np.sum(np.abs(np.atleast_2d(np.asarray(M, dtype=float))), axis=1)


def _sigmoid(v: float) -> float:
    return 1.0 / (1.0 + math.exp(-v))


def gate_bounds(params: Mapping[str, np.ndarray]) -> tuple[float, float, float]:
    """Bounds ``(σ̄_z, σ̄_r, φ̄_h)`` of the gates on ``‖x‖∞ ≤ 1``, ``‖u‖∞ ≤ 1``.

    ``σ̄_z = σ(‖[W_z U_z b_z]‖∞)``, ``σ̄_r = σ(‖[W_r U_r b_r]‖∞)``,
    ``φ̄_h = tanh(‖[W_h U_h b_h]‖∞)`` (``th:stability-bonassi``, ``eq:gates-bounds``).
    """
    return (_sigmoid(_gate_norm(params, "z")), _sigmoid(_gate_norm(params, "r")),
            math.tanh(_gate_norm(params, "h")))


def _gate_norm(params: Mapping[str, np.ndarray], g: str) -> float:
    """``‖[W_g U_g b_g]‖∞``, the argument of the gate bound of gate ``g`` (``z``, ``r``, ``h``)."""
    return inf_norm(np.hstack([params[f"W_{g}"], params[f"U_{g}"],
                               np.reshape(params[f"b_{g}"], (-1, 1))]))


def check_gates(params: Mapping[str, np.ndarray], source: str | None = None) -> None:
    """Raise when the update gate saturates: σ̄_z rounds to 1 in floating point.

    ``ν`` and ``ν_o`` divide by ``1 − σ̄_z`` (``th:stability-bonassi``) and ``ρ_s = ρ_o = 1``
    (no contraction): none of the certificates exists. That happens once
    ``‖[W_z U_z b_z]‖∞`` exceeds about 36.7.

    Raises
    ------
    CertificateError
        One line naming σ̄_z and its argument (prefixed by ``source``, the model file, when
        given); also when that argument is not finite (NaN weights).
    """
    norm = _gate_norm(params, "z")
    where = f"{source}: " if source else ""
    if not math.isfinite(norm):
        raise CertificateError(f"{where}sigma_z (σ̄_z = σ(‖[W_z U_z b_z]‖∞), th:stability-bonassi) "
                         f"is undefined: ‖[W_z U_z b_z]‖∞ = {norm}, the weights are not finite")
    if 1.0 - _sigmoid(norm) > 0:
        return
    raise CertificateError(
        f"{where}sigma_z (σ̄_z = σ(‖[W_z U_z b_z]‖∞) = σ({norm:.6g}), "
        "th:stability-bonassi) rounds to 1: the update gate saturates, 1 − σ̄_z = 0, so nu "
        "and nu_o (÷ (1 − σ̄_z)) are undefined and rho_s = 1; the model has no certificate "
        "(train with a smaller update-gate bias, or cap it: cosim train --sigma-z-max)")


def _index(params: Mapping[str, np.ndarray], Ur: np.ndarray, Uz: np.ndarray) -> float:
    """``‖U_h‖∞ (¼‖Ur‖∞ + σ̄_r) + ¼ (1 + φ̄_h)/(1 − σ̄_z) ‖Uz‖∞`` (ν, ν_o).

    Raises :class:`CertificateError` when σ̄_z rounds to 1 (:func:`check_gates`).
    """
    check_gates(params)
    sz, sr, ph = gate_bounds(params)
    return (inf_norm(params["U_h"]) * (0.25 * inf_norm(Ur) + sr)
            + 0.25 * (1.0 + ph) / (1.0 - sz) * inf_norm(Uz))


def nu(params: Mapping[str, np.ndarray]) -> float:
    """δISS index ``ν`` of ``th:stability-bonassi``; the model is δISS when ``ν < 1``.

    ``ν = ‖U_h‖∞ (¼‖U_r‖∞ + σ̄_r) + ¼ (1 + φ̄_h)/(1 − σ̄_z) ‖U_z‖∞``
    (``eq:condition-deltaiss-gru``).
    """
    return _index(params, params["U_r"], params["U_z"])


def contraction(sigma_z: float, index: float) -> float:
    """``σ̄_z + (1 − σ̄_z)·index``: ``ρ_s`` from ``ν`` (``lem:Vs``), ``ρ_o`` from ``ν_o``
    (``lem:Vo``)."""
    return sigma_z + (1.0 - sigma_z) * index


def rho_s(params: Mapping[str, np.ndarray]) -> float:
    """Contraction rate ``ρ_s = σ̄_z + (1 − σ̄_z) ν`` of ``V_s = ‖x_a − x_b‖∞`` (``lem:Vs``,
    ``eq:incremental-lyap-neg-def``)."""
    return contraction(gate_bounds(params)[0], nu(params))


def c_s(params: Mapping[str, np.ndarray], L: np.ndarray) -> np.ndarray:
    """Constraint gain ``c_s(j) = ‖(L U_o)_(j*)‖∞`` of ``lem:Vs``
    (``eq:incremental-lyap-constraints``); one entry per row of ``L``."""
    return row_norms(np.asarray(L, dtype=float) @ params["U_o"])


# --------------------------------------------------------------------------------------
# Observer (lem:Vo)
# --------------------------------------------------------------------------------------
def nu_o(params: Mapping[str, np.ndarray], L_z: np.ndarray, L_r: np.ndarray) -> float:
    """Observer index ``ν_o`` of ``lem:Vo`` (``eq:condition-observer-convergence``).

    ``ν_o = ‖U_h‖∞ (¼‖U_r − L_r U_o‖∞ + σ̄_r) + ¼ (1 + φ̄_h)/(1 − σ̄_z) ‖U_z − L_z U_o‖∞``.
    """
    Uo = params["U_o"]
    return _index(params, params["U_r"] - L_r @ Uo, params["U_z"] - L_z @ Uo)


def rho_o(params: Mapping[str, np.ndarray], L_z: np.ndarray, L_r: np.ndarray) -> float:
    """Contraction rate ``ρ_o = σ̄_z + (1 − σ̄_z) ν_o`` of ``V_o`` (``lem:Vo``,
    ``eq:lyap-observer-neg-def``)."""
    return contraction(gate_bounds(params)[0], nu_o(params, L_z, L_r))


def c_o(params: Mapping[str, np.ndarray], L: np.ndarray) -> np.ndarray:
    """Constraint gain ``c_o(j) = ‖(L U_o)_(j*)‖∞`` of ``lem:Vo``
    (``eq:lyap-observer-constraint``); equal to :func:`c_s`."""
    return c_s(params, L)


def kappa(params: Mapping[str, np.ndarray], L_z: np.ndarray, L_r: np.ndarray) -> float:
    """Gain of the output perturbation in ``lem:Vo`` (``eq:lyap-observer-neg-def``).

    ``κ = ¼ (1 + φ̄_h) ‖L_z‖∞ + ¼ σ̄_z ‖U_h‖∞ ‖L_r‖∞``.
    """
    sz, _, ph = gate_bounds(params)
    return 0.25 * (1.0 + ph) * inf_norm(L_z) + 0.25 * sz * inf_norm(params["U_h"]) * inf_norm(L_r)


def L_max(params: Mapping[str, np.ndarray], L_z: np.ndarray, L_r: np.ndarray) -> float:
    """Gain of the estimation error on the observer correction (``lem:Vo``,
    ``eq:lyap-observer-max-gain``).

    ``L_max = ¼ (1 + φ̄_h) ‖L_z U_o‖∞ + ¼ σ̄_z ‖U_h‖∞ ‖L_r U_o‖∞``.
    """
    sz, _, ph = gate_bounds(params)
    Uo = params["U_o"]
    return (0.25 * (1.0 + ph) * inf_norm(L_z @ Uo)
            + 0.25 * sz * inf_norm(params["U_h"]) * inf_norm(L_r @ Uo))


def w_L(L: np.ndarray, w_y_bar: float) -> np.ndarray:
    """``w_L(j) = Σ_k |L_jk| w̄_y`` = ``max_{w_y ∈ W_y} L_(j*) w_y`` (``eq:optimization``,
    ``eq:wL-max``)."""
    return np.sum(np.abs(np.asarray(L, dtype=float)), axis=1) * float(w_y_bar)


def tightening_parameters(N: int, rho_o: float, rho_s: float, L_max: float, c_s: np.ndarray,
                          c_o: np.ndarray, w_bar: float) -> tuple[np.ndarray, np.ndarray]:
    """Tightening coefficients ``a_i, b_i``, ``i = 0..N``
    (``eq:constraint_tightening_parameters``).

    ``a_0 = c_o``, ``b_0 = 0``, ``a_{i+1} = ρ_o a_i + ρ_s^i L_max c_s``,
    ``b_{i+1} = b_i + a_i w̄ + c_s ρ_s^i w̄``.

    Returns
    -------
    a, b : (N + 1, q) arrays
    """
    c_s = np.asarray(c_s, dtype=float)
    a = np.empty((N + 1, c_s.size))
    b = np.empty_like(a)
    a[0], b[0] = c_o, 0.0
    for i in range(N):
        a[i + 1] = rho_o * a[i] + rho_s**i * L_max * c_s
        b[i + 1] = b[i] + a[i] * w_bar + c_s * rho_s**i * w_bar
    return a, b


def e_o_sequence(e_o0: float, rho_o: float, w_bar: float, steps: int) -> np.ndarray:
    """``ê_o,0 … ê_o,steps`` of ``eq:eo-evolution``: ``ê_o,k+1 = ρ_o ê_o,k + w̄``."""
    e = np.empty(steps + 1)
    e[0] = e_o0
    for k in range(steps):
        e[k + 1] = rho_o * e[k] + w_bar
    return e


def e_inf(rho_o: float, w_bar: float) -> float:
    """Limit ``ē_∞ = w̄ / (1 − ρ_o)`` of ``eq:eo-evolution`` (``inf`` when ``ρ_o ≥ 1``)."""
    return w_bar / (1.0 - rho_o) if rho_o < 1 else math.inf


def terminal_weight(n: int, Q: np.ndarray, rho_s: float) -> float:
    """Smallest admissible terminal weight ``s = n λ_max(Q) / (1 − ρ_s²)``
    (``eq:definition_s``); ``inf`` when ``ρ_s ≥ 1``."""
    lam = float(np.max(np.linalg.eigvalsh(np.asarray(Q, dtype=float))))
    return n * lam / (1.0 - rho_s**2) if rho_s < 1 else math.inf
