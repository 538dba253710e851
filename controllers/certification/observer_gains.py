"""The observer gains minimising ``ν_o`` (``lem:Vo``): one linear program per row.

The gains of ``eq:observer`` enter ``ν_o`` through ``‖U_r − L_r U_o‖∞`` and
``‖U_z − L_z U_o‖∞``; the ∞-norm is the largest row sum of absolute values, and each row of
``U − L U_o`` depends on one row of ``L`` only, so the minimising gains are one ℓ1 fit per row
(paper section V). :mod:`controllers.certification.certificates` uses them as the reference
gains of the gain scale ``θ`` (``L = θ·L_LP``); :mod:`controllers.certification.gain_design`
chooses ``θ``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from controllers.errors import SolverError

__all__ = ["observer_gains_lp"]


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
