"""Admissible reference governor for set-point changes (an engineering layer outside the paper).

Theorem ``th:feasibility-stability`` holds for one fixed set-point ``ȳ``: the FHOCP
``eq:optimization`` stays feasible because the shifted previous solution with ``ū`` appended
reaches the terminal set ``‖x_N − x̄‖∞ ≤ α``. After a set-point change the terminal set moves
to the new ``x̄`` and, for a large step, no input sequence of ``N`` stages reaches it: the
FHOCP is infeasible (or IPOPT needs many iterations) for a while. The paper gives no
guarantee across set-point changes.

The governor moves the set-point ``v`` handed to the FHOCP from the current one towards the
requested ``r`` only as far as a *known feasible* input sequence exists for it:

    v⁺ = v + λ (r − v),   λ = the largest of 1, 1/2, 1/4, … (``levels`` values) such that
    a candidate sequence, rolled out from ``x̂_k``, satisfies every constraint of
    ``eq:optimization`` for ``(x̄(v⁺), ū(v⁺), α(v⁺))``; ``λ = 0`` (keep ``v``) otherwise.

Candidates: the previous plan shifted by one stage with ``ū(v⁺)`` appended (the candidate of
the theorem's proof) and the same sequence offset by ``ū(v⁺) − ū(v)`` (the input change a
near-linear plant needs). The FHOCP is then warm started from the feasible candidate, and the
controller's fallback applies that candidate when a solve fails, so the applied sequence is
feasible for the governed set-point at every step. The admissible set-points (Assumption 1
and ``eq:condition-recursive-feasibility``) form a polytope, so every point of the segment
between two admissible set-points is admissible too. Once ``v = r`` the controller is the
paper's.

Equilibria along the segment come from a Newton continuation from ``(x̄(v), ū(v))``
(:func:`equilibrium_newton`, a few 22×22 solves) instead of the multi-start least squares of
:func:`controllers.equilibrium.equilibrium`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers import gru
from controllers.equilibrium import jacobians

#: Residual ∞-norm accepted for an equilibrium from Newton's method (normalised units).
EQ_TOL = 1e-11


def equilibrium_newton(params: Mapping[str, np.ndarray], y: np.ndarray, x0: np.ndarray,
                       u0: np.ndarray, max_iter: int = 20,
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """Equilibrium ``x = f(x, u)``, ``U_o x + b_o = y`` (``eq:gru``) by Newton's method from
    ``(x0, u0)``; ``None`` when it does not converge or leaves ``‖u‖∞ ≤ 1``."""
    n = x0.shape[0]
    m = u0.shape[0]
    Uo, bo = params["U_o"], params["b_o"]
    x, u = np.array(x0, dtype=float), np.array(u0, dtype=float)
    K = np.zeros((n + Uo.shape[0], n + m))
    eye = np.eye(n)
    for _ in range(max_iter):
        F = np.concatenate([gru.step(params, x, u) - x, Uo @ x + bo - y])
        if np.max(np.abs(F)) < EQ_TOL:
            return (x, u) if np.max(np.abs(u)) <= 1.0 else None
        f_x, f_u = jacobians(params, x, u)
        K[:n, :n] = f_x - eye
        K[:n, n:] = f_u
        K[n:, :n] = Uo
        try:
            d = np.linalg.solve(K, -F)
        except np.linalg.LinAlgError:
            return None
        x = x + d[:n]
        u = u + d[n:]
    return None


@dataclass
class GovernorStep:
    """Outcome of one governor step: the fraction ``lam`` of ``r − v`` moved, the new
    set-point data and the feasible candidate sequence (``None`` when ``lam == 0``)."""

    lam: float
    y: np.ndarray
    x_bar: np.ndarray
    u_bar: np.ndarray
    alpha: float
    candidate: np.ndarray | None


class ReferenceGovernor:
    """Feasibility-based reference governor (see the module docstring).

    Parameters
    ----------
    cert : controllers.certificates.Certificate
        Gives ``α(ȳ)`` (``eq:def-alpha``) and the admissibility checks.
    fhocp : controllers.mpc.FHOCP
        Gives the tightened bounds and the rollout.
    levels : int
        Number of step fractions tried: ``1, 1/2, …, 2^{1−levels}``.
    """

    def __init__(self, cert: Any, fhocp: Any, levels: int = 5) -> None:
        self.cert = cert
        self.fhocp = fhocp
        self.params = cert.params
        self.levels = int(levels)

    def feasible(self, x_hat: np.ndarray, e_o: float, u_seq: np.ndarray, x_bar: np.ndarray,
                 alpha: float) -> bool:
        """``u_seq`` satisfies every constraint of ``eq:optimization`` from ``x̂``."""
        fh = self.fhocp
        x = fh.rollout(x_hat, u_seq)
        if np.max(x[1: fh.N] @ fh.LUo.T - fh.tightened_bounds(e_o)[1:]) > 0.0:
            return False
        return bool(np.max(np.abs(x[fh.N] - x_bar)) <= alpha)

    def step(self, x_hat: np.ndarray, e_o: float, v: np.ndarray, x_bar: np.ndarray,
             u_bar: np.ndarray, r: np.ndarray, plan: np.ndarray | None,
             lam_max: float = 1.0) -> GovernorStep:
        """Move from the current set-point ``v`` (with ``x̄, ū``) towards ``r`` by at most
        ``lam_max (r − v)``."""
        hold = GovernorStep(0.0, v, x_bar, u_bar, float("nan"), None)
        if plan is None:
            return hold
        lam = float(lam_max)
        for _ in range(self.levels):
            y = v + lam * (r - v)
            if self.cert.failures(y):
                lam *= 0.5
                continue
            eq = equilibrium_newton(self.params, y, x_bar, u_bar)
            if eq is not None:
                xb, ub = eq
                alpha = self.cert.alpha(y)
                shifted = np.vstack([plan[1:], ub])
                for cand in (shifted, np.clip(shifted + (ub - u_bar), -1.0, 1.0)):
                    if self.feasible(x_hat, e_o, cand, xb, alpha):
                        return GovernorStep(lam, y, xb, ub, alpha, cand)
            lam *= 0.5
        return hold
