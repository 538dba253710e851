"""The paper's certificates: δISS, observer gains, constraint tightening, terminal ingredients.

Every quantity of the theory of Schimperna & Magni is computed here from the GRU weights and
the design choices (horizon ``N``, weights ``Q``/``R``, observer gains, ``ê_o,0``, ``w̄_y``),
in the model's NORMALISED units, under the paper's names:

- ``sigma_z, sigma_r, phi_h``: gate bounds σ̄_z, σ̄_r, φ̄_h (``th:stability-bonassi``);
- ``nu``: δISS index ν, δISS when ν < 1 (``eq:condition-deltaiss-gru``);
- ``rho_s, c_s``: contraction and constraint gain of V_s (``lem:Vs``);
- ``L_z, L_r``: observer gains (``eq:observer``);
- ``nu_o, rho_o, c_o, kappa, L_max``: observer index, contraction, constraint gain, gain of
  w_y and of the estimation error (``lem:Vo``);
- ``w_y_bar, w_bar``: bound of w_y and w̄ = κ w̄_y (``eq:w-bar``);
- ``w_L``: w_L(j) = Σ_k |L_jk| w̄_y (``eq:optimization``);
- ``a, b``: tightening coefficients, i = 0..N (``eq:constraint_tightening_parameters``);
- ``e_o0, e_inf``: ê_o,0 and ē_∞ = w̄ / (1 − ρ_o) (``eq:eo-evolution``);
- ``s``: terminal weight n λ_max(Q) / (1 − ρ_s²) (``eq:definition_s``);
- ``alpha``: terminal set radius for a set-point (``eq:def-alpha``); Assumption 1
  (``ass:setpoint``) and ``eq:condition-recursive-feasibility`` per set-point.

Norms. ``‖M‖∞`` of a matrix is the induced ∞-norm, the largest row sum of absolute values.
The paper writes ``‖(L U_o)_(j*)‖∞`` for a ROW: the proof of ``lem:Vs`` uses it as the gain
of ``(L U_o)_(j*) Δx ≤ ‖(L U_o)_(j*)‖∞ ‖Δx‖∞``, which holds for the induced norm of the
1×n matrix, i.e. the sum of absolute values of the row; that is what ``c_s``, ``c_o`` and the
denominator of ``alpha`` use here.

Typos of the paper handled here: the terminal cost is ``s ‖x_N − x̄‖∞²`` (the paper prints a
``+``), and the proof of ``th:feasibility-stability`` writes ``(1 + ρ_s²)`` where
``eq:definition_s`` (used here) needs ``(1 − ρ_s²)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.problem import FOURTANK, ControlProblem
from cosim.errors import CosimError

#: Keys of :meth:`Certificate.to_json`, in order (the paper's names).
JSON_KEYS = ("sigma_z", "sigma_r", "phi_h", "nu", "rho_s", "c_s", "L_z", "L_r", "nu_o",
             "rho_o", "c_o", "kappa", "L_max", "w_y_bar", "w_bar", "w_L", "a", "b", "e_o0",
             "e_inf", "s", "alpha", "assumption_1", "recursive_feasibility")


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
    CosimError
        One line naming σ̄_z and its argument (prefixed by ``source``, the model file, when
        given); also when that argument is not finite (NaN weights).
    """
    norm = _gate_norm(params, "z")
    where = f"{source}: " if source else ""
    if not math.isfinite(norm):
        raise CosimError(f"{where}sigma_z (σ̄_z = σ(‖[W_z U_z b_z]‖∞), th:stability-bonassi) "
                         f"is undefined: ‖[W_z U_z b_z]‖∞ = {norm}, the weights are not finite")
    if 1.0 - _sigmoid(norm) > 0:
        return
    raise CosimError(
        f"{where}sigma_z (σ̄_z = σ(‖[W_z U_z b_z]‖∞) = σ({norm:.6g}), "
        "th:stability-bonassi) rounds to 1: the update gate saturates, 1 − σ̄_z = 0, so nu "
        "and nu_o (÷ (1 − σ̄_z)) are undefined and rho_s = 1; the model has no certificate "
        "(train with a smaller update-gate bias, or cap it: cosim train --sigma-z-max)")


def _index(params: Mapping[str, np.ndarray], Ur: np.ndarray, Uz: np.ndarray) -> float:
    """``‖U_h‖∞ (¼‖Ur‖∞ + σ̄_r) + ¼ (1 + φ̄_h)/(1 − σ̄_z) ‖Uz‖∞`` (ν, ν_o).

    Raises :class:`CosimError` when σ̄_z rounds to 1 (:func:`check_gates`).
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


def _l1_fit_row(c: np.ndarray, A: np.ndarray) -> np.ndarray:
    """``argmin_l ‖c − A l‖₁`` (a linear program), ties broken by the smallest ``‖l‖₁``.

    Variables ``[l, t]`` with ``−t ≤ c − A l ≤ t``; minimise ``Σ t``. A second LP then
    minimises ``‖l‖₁`` among the solutions whose residual is within 1e-12 (relative) of
    the optimum: smaller gains give smaller ``κ`` and ``L_max`` for the same ``ν_o``.
    """
    from scipy.optimize import linprog

    n, p = A.shape
    eye = np.eye(n)
    # c − A l ≤ t  →  −A l − t ≤ −c ;  −(c − A l) ≤ t  →  A l − t ≤ c
    A_ub = np.block([[-A, -eye], [A, -eye]])
    b_ub = np.concatenate([-c, c])
    cost = np.concatenate([np.zeros(p), np.ones(n)])
    bounds = [(None, None)] * p + [(0, None)] * n
    res = linprog(cost, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if res.status != 0:
        raise CosimError(f"observer-gain linear program failed: {res.message}")
    best = float(res.fun)
    # Tie-break: min ‖l‖₁ s.t. residual ≤ best (variables [l, t, v], |l| ≤ v).
    slack = best * (1 + 1e-12) + 1e-15
    Z = np.zeros
    A2 = np.vstack([
        np.hstack([-A, -eye, Z((n, p))]),
        np.hstack([A, -eye, Z((n, p))]),
        np.hstack([Z(p), np.ones(n), Z(p)])[None, :],
        np.hstack([np.eye(p), Z((p, n)), -np.eye(p)]),
        np.hstack([-np.eye(p), Z((p, n)), -np.eye(p)]),
    ])
    b2 = np.concatenate([-c, c, [slack], Z(p), Z(p)])
    cost2 = np.concatenate([Z(p), Z(n), np.ones(p)])
    res2 = linprog(cost2, A_ub=A2, b_ub=b2, bounds=bounds + [(0, None)] * p, method="highs")
    if res2.status == 0 and np.abs(c - A @ res2.x[:p]).sum() <= best * (1 + 1e-10) + 1e-14:
        return res2.x[:p]
    return res.x[:p]


def observer_gains_lp(params: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Observer gains ``(L_z, L_r)`` minimising ``ν_o`` (``lem:Vo``, paper section V).

    ``ν_o`` grows with ``‖U_r − L_r U_o‖∞`` and ``‖U_z − L_z U_o‖∞`` separately, and the
    ∞-norm is the largest row sum of absolute values, whose rows depend on disjoint rows of
    the gain; so each row ``i`` is one linear program
    ``min ‖(U_r)_(i*) − (L_r)_(i*) U_o‖₁`` (and the same for ``U_z``/``L_z``), and the rows'
    optima minimise the maximum. Ties are broken towards the smallest gains.
    """
    Uo = np.asarray(params["U_o"], dtype=float)
    A = Uo.T  # row i of U − L U_o, transposed: U_i − U_o^T l_i
    gains = []
    for name in ("U_z", "U_r"):
        U = np.asarray(params[name], dtype=float)
        gains.append(np.vstack([_l1_fit_row(U[i], A) for i in range(U.shape[0])]))
    return gains[0], gains[1]


# --------------------------------------------------------------------------------------
# Constraints and tightening (eq:output-constraint, eq:constraint_tightening_parameters)
# --------------------------------------------------------------------------------------
def output_constraints(model: Any, problem: ControlProblem = FOURTANK) -> tuple[np.ndarray,
                                                                               np.ndarray]:
    """``(L, h)`` of ``eq:output-constraint`` (``L y ≤ h``) in the model's normalised units.

    For each model output ``j`` (matched by name with ``problem.outputs``) two rows:
    ``+y_j ≤ (max − offset)/scale`` and ``−y_j ≤ −(min − offset)/scale``; a negative scale
    swaps the two bounds.
    """
    names = list(model.output_names)
    rows, rhs = [], []
    bounds = dict(zip(problem.outputs, problem.output_bounds, strict=True))
    for j, name in enumerate(names):
        if name not in bounds:
            raise CosimError(f"model output {name!r} has no bounds in the control problem "
                             f"(outputs {', '.join(problem.outputs)})")
        lo, hi = bounds[name]
        off, sc = float(model.y_offset[j]), float(model.y_scale[j])
        nlo, nhi = sorted(((lo - off) / sc, (hi - off) / sc))
        e = np.zeros(len(names))
        e[j] = 1.0
        rows += [e, -e]
        rhs += [nhi, -nlo]
    return np.array(rows), np.array(rhs)


def constraint_names(model: Any, problem: ControlProblem = FOURTANK) -> list[str]:
    """Readable names of the rows of :func:`output_constraints` (e.g. ``h1 <= 2 m``)."""
    bounds = dict(zip(problem.outputs, problem.output_bounds, strict=True))
    units = dict(zip(problem.outputs, problem.output_units, strict=True))
    names = []
    for j, name in enumerate(model.output_names):
        lo, hi = bounds[name]
        if model.y_scale[j] < 0:
            lo, hi = hi, lo
        names += [f"{name} <= {hi:g} {units[name]}", f"{name} >= {lo:g} {units[name]}"]
    return names


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


# --------------------------------------------------------------------------------------
# The certificate
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Reference:
    """Set-point data of the FHOCP (normalised): ``ȳ``, equilibrium ``(x̄, ū)`` and ``α``
    (``eq:def-alpha``)."""

    y_bar: np.ndarray
    x_bar: np.ndarray
    u_bar: np.ndarray
    alpha: float


@dataclass
class Certificate:
    """Every quantity of the theory for one model and one design, paper names as attributes.

    Set-point dependent quantities (``alpha``, Assumption 1, ``eq:condition-recursive-
    feasibility``) are methods taking the set-point in normalised units. All arrays indexed
    by constraint ``j`` have ``q`` entries (rows of ``L``); ``a`` and ``b`` are ``(N+1, q)``.
    """

    params: dict[str, np.ndarray]
    N: int
    Q: np.ndarray
    R: np.ndarray
    L: np.ndarray
    h: np.ndarray
    sigma_z: float
    sigma_r: float
    phi_h: float
    nu: float
    rho_s: float
    c_s: np.ndarray
    L_z: np.ndarray
    L_r: np.ndarray
    nu_o: float
    rho_o: float
    c_o: np.ndarray
    kappa: float
    L_max: float
    w_y_bar: float
    w_bar: float
    w_L: np.ndarray
    a: np.ndarray
    b: np.ndarray
    e_o0: float
    e_inf: float
    s: float
    gain_scale: float | None = None
    model: Any = field(default=None, repr=False)
    row_names: list[str] | None = None

    # -- dimensions and derived scalars ----------------------------------------------------
    @property
    def n(self) -> int:
        """Number of GRU states."""
        return int(self.params["U_z"].shape[0])

    @property
    def q(self) -> int:
        """Number of output constraints (rows of ``L``)."""
        return int(self.L.shape[0])

    @property
    def e_tilde(self) -> float:
        """``ẽ_o = max(ê_o,0, ē_∞)``, the largest ``ê_o,k`` over ``k ≥ 0`` (``eq:def-alpha``;
        ``ê_o,k`` is monotone, ``eq:eo-evolution``)."""
        return max(self.e_o0, self.e_inf)

    def e_o(self, steps: int, e_o0: float | None = None) -> np.ndarray:
        """``ê_o,0 … ê_o,steps`` (``eq:eo-evolution``)."""
        return e_o_sequence(self.e_o0 if e_o0 is None else e_o0, self.rho_o, self.w_bar, steps)

    def tightened_bounds(self, e_o: float) -> np.ndarray:
        """Right-hand sides ``h − a_i ê_o − b_i − w_L`` for ``i = 0..N``, shape ``(N+1, q)``.

        The FHOCP constraint ``eq:optimization-constraint`` is
        ``L (U_o x_{i|k} + b_o) ≤ tightened_bounds(ê_o,k)[i]`` for ``i = 0..N−1``.
        """
        return self.h[None, :] - self.a * e_o - self.b - self.w_L[None, :]

    def alpha_min(self) -> float:
        """Smallest ``α`` satisfying ``eq:condition-recursive-feasibility`` for every
        ``k ≥ 0``: ``ρ_s^N (L_max ẽ_o + w̄) / (1 − ρ_s)``."""
        if self.rho_s >= 1:
            return math.inf
        return self.rho_s**self.N * (self.L_max * self.e_tilde + self.w_bar) / (1 - self.rho_s)

    # -- set-point dependent ---------------------------------------------------------------
    def _margins(self, y_bar_norm: Sequence[float]) -> np.ndarray:
        y = np.asarray(y_bar_norm, dtype=float)
        return (-self.L @ y + self.h - self.e_tilde * self.a[self.N] - self.b[self.N]
                - self.w_L)

    def alpha(self, y_bar_norm: Sequence[float]) -> float:
        """Terminal set radius ``α`` for the set-point ``ȳ`` (normalised), ``eq:def-alpha``.

        ``α = min_j (−L_(j*) ȳ + h_j − ẽ_o a_N(j) − b_N(j) − w_L(j)) / ‖(L U_o)_(j*)‖∞``.
        Rows with ``‖(L U_o)_(j*)‖∞ = 0`` do not restrict ``α``.
        """
        m = self._margins(y_bar_norm)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios = np.where(self.c_s > 0, m / np.where(self.c_s > 0, self.c_s, 1.0), np.inf)
        return float(np.min(ratios))

    def assumption_1(self, y_bar_norm: Sequence[float]) -> bool:
        """``ass:setpoint``: ``L ȳ < h − ẽ_o a_N − b_N − w_L`` (every row)."""
        return bool(np.all(self._margins(y_bar_norm) > 0))

    def recursive_feasibility(self, y_bar_norm: Sequence[float]) -> bool:
        """``eq:condition-recursive-feasibility`` for all ``k ≥ 0``:
        ``ρ_s^N (L_max ê_o,k + w̄) ≤ α (1 − ρ_s)``.

        ``ê_o,k`` is monotone (``eq:eo-evolution``), so the worst ``k`` has
        ``ê_o,k = ẽ_o = max(ê_o,0, ē_∞)``.
        """
        if self.rho_s >= 1 or not math.isfinite(self.e_tilde):
            return False
        lhs = self.rho_s**self.N * (self.L_max * self.e_tilde + self.w_bar)
        return bool(lhs <= self.alpha(y_bar_norm) * (1 - self.rho_s))

    def admissible_box(self) -> np.ndarray:
        """Right-hand side ``h − ẽ_o a_N − b_N − w_L − α_min c_s`` of the set-points
        satisfying Assumption 1 and ``eq:condition-recursive-feasibility``:
        ``{ȳ : L ȳ ≤ admissible_box()}`` (normalised units, a polytope; a box for the
        four tanks' bounds)."""
        return (self.h - self.e_tilde * self.a[self.N] - self.b[self.N] - self.w_L
                - self.alpha_min() * self.c_s)

    # -- hypotheses ------------------------------------------------------------------------
    def failures(self, y_bar_norm: Sequence[float] | None = None) -> list[str]:
        """Each failed hypothesis of ``th:feasibility-stability``, as one message each.

        Without a set-point only the design conditions (ν < 1, ν_o < 1) are checked.
        """
        out = []
        if not self.nu < 1:
            out.append(f"δISS condition (th:stability-bonassi) fails: nu = {self.nu:.6g} >= 1")
        if not self.nu_o < 1:
            out.append("observer condition (eq:condition-observer-convergence) fails: "
                       f"nu_o = {self.nu_o:.6g} >= 1")
        if y_bar_norm is not None and out:
            out.append("set-point checks (Assumption 1, alpha, eq:condition-recursive-"
                       "feasibility) not evaluated: they need nu < 1 and nu_o < 1")
        elif y_bar_norm is not None:
            a = self.alpha(y_bar_norm)
            if not self.assumption_1(y_bar_norm):
                m = self._margins(y_bar_norm)
                j = int(np.argmin(m))
                row = self.row_names[j] if self.row_names else f"row {j}"
                out.append(f"Assumption 1 (ass:setpoint) fails: constraint {row} has "
                           f"margin {m[j]:.6g} <= 0 (h - e_tilde a_N - b_N - w_L - L y_bar)")
            if not a > 0:
                out.append(f"alpha (eq:def-alpha) = {a:.6g} <= 0: empty terminal set")
            if not self.recursive_feasibility(y_bar_norm):
                out.append("recursive feasibility (eq:condition-recursive-feasibility) fails: "
                           f"alpha = {a:.6g} < alpha_min = {self.alpha_min():.6g} "
                           "= rho_s^N (L_max e_tilde + w_bar)/(1 - rho_s)")
        return out

    def reference(self, y_bar_norm: Sequence[float], *, check: bool = True) -> Reference:
        """Everything the FHOCP needs for a set-point: ``x̄, ū`` and ``α``.

        ``(x̄, ū)`` is the model equilibrium with output ``ȳ`` (:func:`controllers.equilibrium.
        equilibrium`), ``α`` is ``eq:def-alpha``; call again whenever ``ȳ`` changes.

        Raises
        ------
        CosimError
            When ``ȳ`` is not reachable with ``‖ū‖∞ ≤ 1``, or (``check=True``) when a
            hypothesis of ``th:feasibility-stability`` fails at ``ȳ`` (Assumption 1,
            ``eq:condition-recursive-feasibility``, ν < 1, ν_o < 1); one line naming the
            set-point (physical units when the certificate has its model) and the failures.
        """
        from controllers.equilibrium import _describe, equilibrium

        y = np.asarray(y_bar_norm, dtype=float).reshape(-1)
        if check:
            failed = self.failures(y)
            if failed:
                where = _describe(self.model, y) if self.model is not None else str(y.tolist())
                raise CosimError(f"set-point {where}: " + "; ".join(failed))
        x_bar, u_bar = equilibrium(self.model if self.model is not None else self.params, y)
        return Reference(y_bar=y, x_bar=x_bar, u_bar=u_bar, alpha=self.alpha(y))

    def ok(self, y_bar_norm: Sequence[float] | None = None) -> bool:
        """``True`` when :meth:`failures` is empty."""
        return not self.failures(y_bar_norm)

    # -- output --------------------------------------------------------------------------
    def to_json(self, setpoint: Sequence[float] | None = None) -> dict[str, Any]:
        """A JSON-ready dict with exactly :data:`JSON_KEYS` (arrays as lists).

        ``setpoint`` is ``ȳ`` in normalised units; without it ``alpha``, ``assumption_1``
        and ``recursive_feasibility`` are ``None``. Non-finite scalars (``e_inf`` or ``s``
        when a contraction rate is ≥ 1) are ``None`` too.
        """
        def val(v: Any) -> Any:
            if isinstance(v, np.ndarray):
                return v.tolist()
            if isinstance(v, float) and not math.isfinite(v):
                return None  # JSON has no inf/nan (e.g. e_inf when rho_o >= 1)
            return v

        doc = {k: val(getattr(self, k)) for k in JSON_KEYS[:-3]}
        if setpoint is None:
            doc.update(alpha=None, assumption_1=None, recursive_feasibility=None)
        else:
            doc.update(alpha=val(self.alpha(setpoint)),
                       assumption_1=self.assumption_1(setpoint),
                       recursive_feasibility=self.recursive_feasibility(setpoint))
        return doc


#: Largest prediction horizon accepted (the FHOCP grows linearly with ``N``).
MAX_HORIZON = 1000


def _horizon(N: Any) -> int:
    """``N`` as an int in ``1 … MAX_HORIZON`` (an integer-valued float is accepted)."""
    ok = isinstance(N, (int, np.integer)) and not isinstance(N, bool)
    if isinstance(N, (float, np.floating)) and math.isfinite(N) and float(N).is_integer():
        ok, N = True, int(N)
    if not ok:
        raise CosimError(f"horizon N must be an integer >= 1, got {N!r}")
    if not 1 <= N <= MAX_HORIZON:
        raise CosimError(f"horizon N must be >= 1 and <= {MAX_HORIZON}, got {N}")
    return int(N)


def _weight(value: Any, name: str, size: int, default: float) -> np.ndarray:
    """Cost weight ``Q`` or ``R`` (``eq:optimization``): a symmetric positive definite
    ``(size, size)`` matrix; ``None`` gives ``default · I``."""
    if value is None:
        return default * np.eye(size)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CosimError(f"cost weight {name} must be a {size}x{size} matrix of numbers, "
                         f"got {value!r}") from None
    if arr.shape != (size, size):
        raise CosimError(f"cost weight {name} must be a {size}x{size} matrix, got shape "
                         f"{arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CosimError(f"cost weight {name} has non-finite entries")
    if not np.allclose(arr, arr.T) or np.min(np.linalg.eigvalsh(arr)) <= 0:
        raise CosimError(f"cost weight {name} must be symmetric positive definite")
    return arr


def _gain(value: Any, name: str, n: int, p: int) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n, p):
        raise CosimError(f"observer gain {name} must have shape {(n, p)}, got {arr.shape}")
    return arr


def compute_certificate(model: Any, *, N: int = 15, Q: np.ndarray | None = None,
                        R: np.ndarray | None = None, e_o0: float = 0.02,
                        L_z: np.ndarray | None = None, L_r: np.ndarray | None = None,
                        w_y_bar: float | None = None, gain_scale: float | None = None,
                        L: np.ndarray | None = None, h: np.ndarray | None = None,
                        problem: ControlProblem = FOURTANK) -> Certificate:
    """Compute every certificate quantity for ``model`` (a :class:`GRUModel`).

    Parameters
    ----------
    model : GRUModel
        The δISS GRU (weights and normalisation).
    N : int
        Prediction horizon (paper: 15).
    Q, R : arrays, optional
        Cost weights; default ``I_n`` and ``0.01 I_m`` (paper section V).
    e_o0 : float
        ``ê_o,0`` (paper: 0.02), the assumed initial bound of ``‖x_0 − x̂_0‖∞``.
    L_z, L_r : (n, p) arrays, optional
        Observer gains. Default: ``gain_scale ×`` the LP gains (:func:`observer_gains_lp`)
        when ``gain_scale`` is given, else the gains saved in the model file, else the LP
        gains (``gain_scale = 1``).
    w_y_bar : float, optional
        ``w̄_y`` (normalised); default the model file's ``w_y_bar``.
    gain_scale : float, optional
        ``θ`` in ``L = θ·L_LP`` (see :func:`choose_gain_scale`).
    L, h : arrays, optional
        Output constraints ``L y ≤ h`` (normalised); default from ``problem``
        (:func:`output_constraints`).

    Raises
    ------
    CosimError
        A bad design argument, or a model without certificate: the update gate saturates
        (σ̄_z rounds to 1, :func:`check_gates`; the message names the model file when the
        model has a ``source``).
    """
    params = {k: np.asarray(v, dtype=float) for k, v in model.params.items()}
    n, m = params["W_z"].shape
    p = params["U_o"].shape[0]
    check_gates(params, getattr(model, "source", None))
    N = _horizon(N)
    if (isinstance(e_o0, bool) or not isinstance(e_o0, (int, float, np.number))
            or not (math.isfinite(e_o0) and e_o0 >= 0)):
        raise CosimError(f"e_o0 must be a non-negative number, got {e_o0!r}")
    if gain_scale is not None:
        if (isinstance(gain_scale, bool) or not isinstance(gain_scale, (int, float, np.number))
                or not (math.isfinite(gain_scale) and gain_scale >= 0)):
            raise CosimError(f"gain scale must be a non-negative number, got {gain_scale!r}")
        gain_scale = float(gain_scale)
    Q = _weight(Q, "Q", n, 1.0)
    R = _weight(R, "R", m, 0.01)

    if (L_z is None) != (L_r is None):
        raise CosimError("give both observer gains L_z and L_r, or neither")
    if L_z is not None:
        L_z, L_r = _gain(L_z, "L_z", n, p), _gain(L_r, "L_r", n, p)
        if gain_scale is not None:
            L_z, L_r = gain_scale * L_z, gain_scale * L_r
    elif gain_scale is not None or getattr(model, "L_z", None) is None:
        theta = 1.0 if gain_scale is None else float(gain_scale)
        Lz_lp, Lr_lp = observer_gains_lp(params)
        L_z, L_r, gain_scale = theta * Lz_lp, theta * Lr_lp, theta
    else:
        L_z, L_r = _gain(model.L_z, "L_z", n, p), _gain(model.L_r, "L_r", n, p)

    if w_y_bar is None:
        w_y_bar = getattr(model, "w_y_bar", None)
        if w_y_bar is None:
            raise CosimError("no w_y_bar: the model file has none; estimate it from data "
                             "(cosim certify --data DATA.csv) or pass it")
    w_y_bar = float(w_y_bar)
    row_names = None
    if L is None or h is None:
        L, h = output_constraints(model, problem)
        row_names = constraint_names(model, problem)
    L, h = np.asarray(L, dtype=float), np.asarray(h, dtype=float)

    sz, sr, ph = gate_bounds(params)
    nu_ = nu(params)
    rho_s_ = contraction(sz, nu_)
    cs = c_s(params, L)
    nu_o_ = nu_o(params, L_z, L_r)
    rho_o_ = contraction(sz, nu_o_)
    kap = kappa(params, L_z, L_r)
    lmax = L_max(params, L_z, L_r)
    w_bar = kap * w_y_bar
    a, b = tightening_parameters(N, rho_o_, rho_s_, lmax, cs, cs, w_bar)
    return Certificate(
        params=params, N=int(N), Q=Q, R=R, L=L, h=h, sigma_z=sz, sigma_r=sr, phi_h=ph,
        nu=nu_, rho_s=rho_s_, c_s=cs, L_z=L_z, L_r=L_r, nu_o=nu_o_, rho_o=rho_o_,
        c_o=cs.copy(), kappa=kap, L_max=lmax, w_y_bar=w_y_bar, w_bar=w_bar,
        w_L=w_L(L, w_y_bar), a=a, b=b, e_o0=float(e_o0), e_inf=e_inf(rho_o_, w_bar),
        s=terminal_weight(n, Q, rho_s_), gain_scale=gain_scale, model=model,
        row_names=row_names)


# --------------------------------------------------------------------------------------
# Design lever: the observer-gain scale
# --------------------------------------------------------------------------------------
def choose_gain_scale(model: Any, setpoints_norm: Iterable[Sequence[float]], *,
                      N: int = 15, Q: np.ndarray | None = None, R: np.ndarray | None = None,
                      e_o0: float = 0.02, w_y_bar: float | None = None,
                      L_z: np.ndarray | None = None, L_r: np.ndarray | None = None,
                      grid: Sequence[float] | None = None, iterations: int = 40,
                      **kwargs: Any) -> tuple[float | None, Certificate]:
    """Largest ``θ ∈ [0, 1]`` such that the gains ``θ·L`` pass every hypothesis.

    The prototype found ``α < 0`` with the LP-optimal gains: large gains shrink ``ρ_o`` but
    grow ``κ`` (hence ``w̄``, ``ē_∞``, ``b_i``) and ``L_max`` (hence ``a_i``). This searches
    ``θ`` for ``L = θ·L`` (``L`` = the LP gains of :func:`observer_gains_lp` unless given)
    such that ν < 1, ν_o < 1, Assumption 1 (``ass:setpoint``), ``α > 0`` (``eq:def-alpha``)
    and ``eq:condition-recursive-feasibility`` hold at every set-point. The conditions need
    not be monotone in ``θ``: a grid (1, then 4 points per decade down to 1e-6, then 0) finds
    the largest passing grid value, refined by bisection towards the next larger grid value.

    Returns
    -------
    theta : float or None
        The scale, or ``None`` when even ``θ = 0`` (the open-loop observer, ``rem:observer-
        gains``) fails.
    certificate : Certificate
        At ``theta`` (at ``θ = 0`` when ``theta`` is None).
    """
    setpoints = [np.asarray(y, dtype=float) for y in setpoints_norm]
    check_gates({k: np.asarray(v, dtype=float) for k, v in model.params.items()},
                getattr(model, "source", None))
    if L_z is None or L_r is None:
        L_z, L_r = observer_gains_lp(model.params)
    if grid is None:
        grid = [1.0, *[10 ** (-k / 4) for k in range(1, 25)], 0.0]

    def cert(theta: float) -> Certificate:
        return compute_certificate(model, N=N, Q=Q, R=R, e_o0=e_o0, w_y_bar=w_y_bar,
                                   L_z=theta * L_z, L_r=theta * L_r, **kwargs)

    def passes(c: Certificate) -> bool:
        return not c.failures() and all(c.ok(y) for y in setpoints)

    previous = None
    for theta in grid:
        c = cert(theta)
        if passes(c):
            if previous is not None:  # refine between theta (pass) and previous (fail)
                lo, hi = theta, previous
                for _ in range(iterations):
                    mid = 0.5 * (lo + hi)
                    cm = cert(mid)
                    if passes(cm):
                        lo, c = mid, cm
                    else:
                        hi = mid
                theta = lo
            c.gain_scale = theta
            return theta, c
        previous = theta
    c = cert(0.0)
    c.gain_scale = 0.0
    return None, c


# --------------------------------------------------------------------------------------
# w̄_y from data
# --------------------------------------------------------------------------------------
def w_y_bar_from_data(model: Any, data_csv: Any, split: str = "test",
                      washout: str | None = "val") -> float:
    """``w̄_y``: the largest absolute output error of the model on the test data, normalised.

    The model is simulated open loop (``eq:gru``) on the data's inputs; the error
    ``y_k − ξ_k`` is measured on the rows of ``split`` (paper section V: "maximum absolute
    value of the prediction error on the test dataset in the normalized variables"). The
    simulation starts at the model equilibrium for the first measured output of the
    ``washout`` split (the rows just before the test split, default validation), so that
    the initial state is forgotten (δISS) before the test rows begin; ``washout=None``
    starts at the first test row.

    The CSV is the ``cosim generate-data`` format: ``time,<inputs>,<outputs>,split``.
    """
    from controllers.equilibrium import equilibrium_for_output
    from controllers.gru import simulate
    from cosim.datagen import read_csv

    data = read_csv(data_csv, input_names=list(model.input_names))
    y_all = data.outputs(list(model.output_names))
    keep = data.split == split
    if not np.any(keep):
        raise CosimError(f"{data_csv}: no rows in split {split!r}")
    idx = np.flatnonzero(keep)
    start = idx[0]
    if washout is not None and np.any(data.split == washout):
        w_idx = np.flatnonzero(data.split == washout)
        if w_idx[-1] == start - 1:  # contiguous, just before the test rows
            start = w_idx[0]
    stop = idx[-1] + 1
    u = model.normalize_u(data.u[start:stop])
    y = model.normalize_y(y_all[start:stop])
    x0, _ = equilibrium_for_output(model.params, y[0])
    _, xi = simulate(model.params, x0, u)
    mask = keep[start:stop]
    return float(np.max(np.abs(y[mask] - xi[mask])))
