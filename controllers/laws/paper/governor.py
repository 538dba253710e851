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
(:func:`controllers.equilibrium.equilibrium_newton`, a few (n + p)×(n + m) solves: 22×22 for
the four tanks, in the compiled kernel when there is one, its least-squares steps by the
normal equations when ``m ≠ p``; numpy's otherwise) instead of the multi-start least squares of
:func:`controllers.equilibrium.equilibrium`.

More outputs than inputs (``p > m``): the equilibrium outputs form an ``m``-dimensional
surface, and the points of the segment ``v → r`` between two reachable set-points are in
general not on it. The governor then moves along the surface instead: the equilibrium input
``ū(r)`` is found once per requested ``r``, and ``v⁺`` is the equilibrium output of
``ū(v) + λ (ū(r) − ū(v))`` (``v⁺ = r`` at ``λ = 1``; the state equilibrium by the compiled
kernel's Newton when there is one, a level it does not converge at skipped, as the exported
controller does); each ``v⁺`` is checked for Assumption 1
and ``eq:condition-recursive-feasibility`` as above (the polytope argument does not apply off
the segment).

The largest fraction tried, ``λ_max``, adapts to the solver (:meth:`ReferenceGovernor.
govern`): it halves (down to :data:`LAM_MIN`) after a solve that did not converge and doubles
(up to 1) after a converged solve that followed a move.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.equilibrium import equilibrium_newton, equilibrium_output
from controllers.errors import SetpointError

__all__ = ["LAM_GROW", "LAM_MIN", "GovernorStep", "ReferenceGovernor"]

#: The adaptive step limit ``λ_max``: smallest value, and growth factor after a converged
#: solve that followed a move (it halves after a solve that did not converge).
LAM_MIN = 0.0625
LAM_GROW = 2.0


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
    cert : controllers.certification.certificates.Certificate
        Gives ``α(ȳ)`` (``eq:def-alpha``) and the admissibility checks.
    fhocp : controllers.ocp.fhocp.FHOCP
        Gives the tightened bounds and the rollout.
    levels : int
        Number of step fractions tried: ``1, 1/2, …, 2^{1−levels}``.

    Attributes
    ----------
    lam_max : float
        The largest fraction of ``r − v`` the next step may move (adapted by :meth:`govern`).
    """

    def __init__(self, cert: Any, fhocp: Any, levels: int = 5) -> None:
        self.cert = cert
        self.fhocp = fhocp
        self.params = cert.params
        self.m = int(self.params["W_z"].shape[1])
        self.p = int(self.params["U_o"].shape[0])
        self.levels = int(levels)
        self.reset()

    def reset(self) -> None:
        """Forget the adaptation (a new run): ``λ_max = 1``."""
        self.lam_max = 1.0
        self._moved = False
        self._target: tuple[bytes, tuple[np.ndarray, np.ndarray] | None] | None = None

    def forget_target(self) -> None:
        """Forget the equilibrium kept for the last request (:meth:`target`): the model's
        equilibria moved (its biases hold new measured disturbances)."""
        self._target = None

    def newton(self, y: np.ndarray, x0: np.ndarray,
               u0: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """:func:`controllers.equilibrium.equilibrium_newton` from ``(x0, u0)``: the FHOCP's
        compiled kernel when it has one (same iteration, ~25× faster; the exported
        controller's too), else numpy."""
        kernel = getattr(self.fhocp, "kernel", None)
        if kernel is not None and "eq_newton" in kernel.kernel.c:
            return kernel.eq_newton(y, x0, u0)
        return equilibrium_newton(self.params, y, x0, u0)

    def equilibrium_output(self, u: np.ndarray, x0: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray] | None:
        """``(x, y)``: the state equilibrium ``x = f(x, u)`` from ``x0`` and its output: the
        FHOCP's compiled kernel's Newton and output sum when it has one (``None`` when the
        Newton does not converge; the exported controller's), else numpy's
        :func:`controllers.equilibrium.equilibrium_output`."""
        kernel = getattr(self.fhocp, "kernel", None)
        if kernel is not None and "steady" in kernel.kernel.c:
            x = kernel.steady_state(u, x0)
            return None if x is None else (x, kernel.output(x))
        return equilibrium_output(self.params, u, x0)

    def target(self, r: np.ndarray, x0: np.ndarray,
               u0: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The equilibrium ``(x̄, ū)(r)`` (kept for the last ``r``): the Newton continuation
        from ``(x0, u0)``, else the multi-start least squares; ``None`` when ``r`` is not
        reachable."""
        key = np.asarray(r, dtype=float).tobytes()
        if self._target is None or self._target[0] != key:
            eq = self.newton(r, x0, u0)
            if eq is None:
                try:
                    ref = self.cert.reference(r, check=False,
                                              kernel=getattr(self.fhocp, "kernel", None))
                    eq = (ref.x_bar, ref.u_bar)
                except SetpointError:
                    eq = None
            self._target = (key, eq)
        return self._target[1]

    def govern(self, x_hat: np.ndarray, e_o: float, v: np.ndarray, x_bar: np.ndarray,
               u_bar: np.ndarray, r: np.ndarray, plan: np.ndarray | None,
               last_success: bool | None) -> GovernorStep:
        """:meth:`step` with ``λ_max`` adapted to the last solve (``None``: no solve yet).

        ``λ_max`` halves after a solve that did not converge (not below :data:`LAM_MIN`) and
        doubles after a converged solve that followed a move (not above 1).
        """
        if last_success is False:
            self.lam_max = max(self.lam_max * 0.5, LAM_MIN)
        elif self._moved and last_success is not None:
            self.lam_max = min(1.0, self.lam_max * LAM_GROW)
        gs = self.step(x_hat, e_o, v, x_bar, u_bar, r, plan, self.lam_max)
        self._moved = gs.lam > 0.0
        return gs

    def feasible(self, x_hat: np.ndarray, e_o: float, u_seq: np.ndarray, x_bar: np.ndarray,
                 alpha: float) -> bool:
        """``u_seq`` satisfies every constraint of ``eq:optimization`` from ``x̂``."""
        viol, dist = self.fhocp.reference.assess(x_hat, u_seq, x_bar, e_o, alpha)
        return bool(not viol > 0.0 and dist <= alpha)

    def step(self, x_hat: np.ndarray, e_o: float, v: np.ndarray, x_bar: np.ndarray,
             u_bar: np.ndarray, r: np.ndarray, plan: np.ndarray | None,
             lam_max: float = 1.0) -> GovernorStep:
        """Move from the current set-point ``v`` (with ``x̄, ū``) towards ``r`` by at most
        ``lam_max (r − v)``."""
        hold = GovernorStep(0.0, v, x_bar, u_bar, float("nan"), None)
        if plan is None:
            return hold
        along = None
        if self.p > self.m:   # along the surface of equilibrium outputs (module docstring)
            along = self.target(r, x_bar, u_bar)
            if along is None:
                return hold
        lam = float(lam_max)
        for _ in range(self.levels):
            if along is None:
                y = v + lam * (r - v)
            elif lam == 1.0:
                y, eq = np.asarray(r, dtype=float), along
            else:
                ub = u_bar + lam * (along[1] - u_bar)
                state = self.equilibrium_output(ub, x_bar)
                if state is None:
                    lam *= 0.5
                    continue
                xb, y = state
                eq = (xb, ub)
            if not self.cert.ok(y):
                lam *= 0.5
                continue
            if along is None:
                eq = self.newton(y, x_bar, u_bar)
            if eq is not None:
                xb, ub = eq
                alpha = self.cert.alpha(y)
                shifted = np.vstack([plan[1:], ub])
                prefix = self.fhocp.prefix   # the inputs already applied stay as they were
                for cand in (prefix.impose(shifted),
                             prefix.impose(np.clip(shifted + (ub - u_bar), -1.0, 1.0))):
                    if self.feasible(x_hat, e_o, cand, xb, alpha):
                        return GovernorStep(lam, y, xb, ub, alpha, cand)
            lam *= 0.5
        return hold
