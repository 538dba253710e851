"""Observer-gain design: the LP gains minimising ``ν_o`` and the gain scale ``θ``.

The gains of ``eq:observer`` that minimise ``ν_o`` (``lem:Vo``; one linear program per row,
paper section V) make ``ρ_o`` small but ``κ`` and ``L_max`` large, and with them ``w̄``,
``ē_∞``, ``a_i``, ``b_i``: on a real model ``α`` is then negative everywhere (the prototype's
finding). The design lever is therefore ``L = θ·L_LP`` with the largest ``θ ∈ [0, 1]`` for
which every hypothesis of ``th:feasibility-stability`` holds at the set-points of interest
(:func:`choose_gain_scale`; ``θ = 0`` is the open-loop observer, ``rem:observer-gains``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from controllers.bounds import check_gates
from controllers.certificates import Certificate, compute_certificate
from controllers.errors import SolverError

__all__ = ["DEFAULT_SETPOINTS", "choose_gain_scale", "observer_gains_lp"]

#: Set-points (physical units, metres) at which the gain scale is chosen when none are
#: given: the 3 × 3 grid {0.5, 1.0, 1.5}² (``cosim certify --auto-gain-scale``, and the
#: robust MPC for a model file without gains).
DEFAULT_SETPOINTS = [(a, b) for a in (0.5, 1.0, 1.5) for b in (0.5, 1.0, 1.5)]


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
        raise SolverError(f"observer-gain linear program failed: {res.message}")
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
