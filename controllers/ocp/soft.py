"""Softened output constraints of the FHOCP: slacks with an exact penalty, solved when the hard
problem has no answer (``eq:optimization`` made solvable from every state; docs:
design/soft-constraints.md).

With ``FHOCP(soft=True)`` (the controller's default; ``hard_constraints = true`` keeps the
paper's hard problem alone) the output rows ``eq:optimization-constraint`` of stages
``i = 1 … N−1``, the tracking law's ``Y_s`` rows and the terminal set ``eq:terminal_constraint``
may be exceeded, at a price::

    L_j (U_o x_i + b_o) + w_L,j − ε_j ≤ h_j − a_ij ê_o − b_ij       (one ε_j per row j of L)
    −t − ε_T ≤ x_N − x̄ ≤ t + ε_T,   0 ≤ t ≤ α,   ε ≥ 0
    cost  +  ρ Σ_k ε_k + ρ_2 Σ_k ε_k²

``ε_j`` is the largest excess of row ``j`` over the horizon (an ℓ∞ slack per row, shared by
the stages and by ``Y_s``'s row ``j``), ``ε_T`` the terminal set's. The linear term makes
the penalty exact (Fletcher 1987, Thm 14.3.1; Kerrigan & Maciejowski 2000): when the hard
problem is feasible and ``ρ`` exceeds the sum of its rows' multipliers at the solution, the
softened problem has the same solution with ``ε = 0``; the quadratic term keeps the QP's
Hessian positive definite. The ``i = 0`` row involves ``x̂`` only and is not part of it.

**Two phases.** Each solve (:meth:`controllers.ocp.fhocp.FHOCP.solve_request`) is first the
hard problem: the slacks fixed at 0 and their weights off (:meth:`Slacks.off`), so that a
problem with an answer gets the paper's, its certified behaviour (``th:feasibility-stability``)
unchanged. Only when that one has no answer (``x̂`` fails the ``i = 0`` row, or the SQP's
QP is infeasible or fails: :data:`~controllers.ocp.solve_status.SOFTEN_AFTER`) the softened
problem is solved from the same guess: the plan that exceeds the rows least, weighed against
the cost. Solving the softened problem at every step would give the same answers (the
penalty is exact), but its slacks' multipliers of order ``ρ`` beside the cost's own cost the
dense QP digits: measured on the four-tank, 40 line-search failures in a step the hard
problem solves in 2 iterations.

:data:`SOFT_MARGIN` sets ``ρ`` from the cost's own scale (:func:`default_weight`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.errors import DesignError
from controllers.ocp.solver_settings import FEAS_TOL

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["QUADRATIC", "SOFT_MARGIN", "Slacks", "default_weight"]

#: ``ρ`` over the cost's scale (:func:`default_weight`).
SOFT_MARGIN = 100.0
#: ``ρ_2 / ρ``: the quadratic term keeps the QP's Hessian positive definite; a larger one
#: made the softened solves slower (on the four-tank from states the hard problem cannot
#: keep: 37 SQP iterations with ρ_2 = ρ, 7 with ρ_2 = 10⁻⁴ ρ).
QUADRATIC = 1e-4


def default_weight(fhocp: FHOCP) -> float:
    """``ρ = SOFT_MARGIN × max(1, s, N λ_max(Q), N λ_max(R), max T)``: the exact penalty's
    weight from the scale of the cost's terms (normalised units; ``T`` the tracking law's
    offset weights; the finite ones)."""
    N = fhocp.N
    scale = [1.0, fhocp.s, N * float(np.max(np.linalg.eigvalsh(fhocp.Q))),
             N * float(np.max(np.linalg.eigvalsh(fhocp.R)))]
    T = getattr(fhocp.reference, "offset_weight", None)
    if T is not None:
        scale.append(float(np.max(T)))
    # a model the theory gives no terminal weight (s = inf) is refused by the design's own
    # checks, in the user's words: the weight here must not stand in their way
    return SOFT_MARGIN * max(v for v in scale if np.isfinite(v))


@dataclass(frozen=True)
class Slacks:
    """The slacks of a softened FHOCP: ``ε = (ε_1 … ε_q, ε_T)`` at ``w[idx]``.

    Attributes
    ----------
    idx : (q + 1,) int array
        Indices of the row slacks then the terminal slack in ``w``.
    rho, rho2 : float
        The penalty's linear and quadratic weights (``ρ Σ ε + ρ_2 Σ ε²``); both 0 in the
        hard phase (:meth:`off`).
    q, n, N : int
        Rows of ``L``, states, horizon.
    """

    idx: np.ndarray
    rho: float
    rho2: float
    q: int
    n: int
    N: int

    @classmethod
    def of(cls, fhocp: FHOCP, weight: float | None, start: int) -> Slacks:
        """The slacks of ``fhocp`` from index ``start`` of ``w`` (weight ``ρ``; ``None``:
        :func:`default_weight`; ``ρ_2 = QUADRATIC ρ``)."""
        rho = default_weight(fhocp) if weight is None else float(weight)
        if not (np.isfinite(rho) and rho > 0):
            raise DesignError(f"soft_weight must be a positive number, got {weight!r}")
        return cls(np.arange(start, start + fhocp.q + 1), rho, QUADRATIC * rho, fhocp.q,
                   fhocp.n, fhocp.N)

    def off(self) -> Slacks:
        """The hard phase's: the same slacks (fixed at 0 by their bounds) without weights."""
        return dataclasses.replace(self, rho=0.0, rho2=0.0)

    @property
    def count(self) -> int:
        """How many: ``q + 1``."""
        return self.q + 1

    # -- the NLP's terms -----------------------------------------------------------------
    def penalty(self, eps: np.ndarray) -> float:
        """``ρ Σ ε + ρ_2 Σ ε²``."""
        return self.rho * float(np.sum(eps)) + self.rho2 * float(np.vdot(eps, eps))

    def gradient(self, eps: np.ndarray) -> np.ndarray:
        """∇ of :meth:`penalty`: ``ρ + 2 ρ_2 ε``."""
        return self.rho + 2.0 * self.rho2 * eps

    def soften(self, g: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """The hard constraint vector ``g`` (output rows of stages 1 … N−1, the terminal rows
        ``x_N − x̄ ∓ t``, then the tracking law's ``Y_s`` rows when present) with the slacks'
        terms: ``− ε_j`` on row ``j``'s rows, ``∓ ε_T`` on the terminal ones."""
        r0, n = (self.N - 1) * self.q, self.n
        out = g.copy()
        out[:r0] -= np.tile(eps[:self.q], self.N - 1)
        out[r0:r0 + n] -= eps[-1]
        out[r0 + n:r0 + 2 * n] += eps[-1]
        out[r0 + 2 * n:] -= eps[:self.q][: g.size - r0 - 2 * n]
        return out

    def jacobian_columns(self, J: np.ndarray) -> None:
        """The slacks' columns of ``∂g/∂w`` (``J``: rows as :meth:`soften`), in place."""
        r0, n, q = (self.N - 1) * self.q, self.n, self.q
        rows = np.arange(r0)
        J[rows, self.idx[rows % q]] = -1.0
        J[r0:r0 + n, self.idx[-1]] = -1.0
        J[r0 + n:r0 + 2 * n, self.idx[-1]] = 1.0
        extra = np.arange(r0 + 2 * n, J.shape[0])
        J[extra, self.idx[extra - r0 - 2 * n]] = -1.0

    def embed(self, grad_or_H: Any, nw: int, wv: np.ndarray, lf: float | None = None
              ) -> Any:
        """The hard problem's gradient (vector) or Hessian (matrix, with ``lf``) over
        ``w[:idx[0]]`` embedded in ``w``'s size with the slacks' terms."""
        k = self.idx[0]
        if lf is None:
            out = np.zeros(nw)
            out[:k] = grad_or_H
            out[self.idx] = self.gradient(wv[self.idx])
            return out
        H = np.zeros((nw, nw))
        H[:k, :k] = grad_or_H
        H[self.idx, self.idx] = 2.0 * lf * self.rho2
        return H

    # -- a plan's ------------------------------------------------------------------------
    def of_plan(self, excess: np.ndarray, distance: float, alpha: float) -> np.ndarray:
        """The slacks a plan is priced with: ``ε_j`` the largest excess of row ``j`` beyond
        the answer check's tolerance :data:`~controllers.ocp.solver_settings.FEAS_TOL`
        (``excess``: stages × q, rows beyond the bounds, ``Y_s``'s as one more stage; an
        answer of the hard phase pays nothing), ``ε_T = max(0, ‖x_N − x̄‖∞ − α − FEAS_TOL)``."""
        eps = np.empty(self.count)
        eps[:self.q] = (np.maximum(0.0, np.max(excess, axis=0) - FEAS_TOL) if excess.size
                        else 0.0)
        eps[-1] = max(0.0, distance - alpha - FEAS_TOL)
        return eps

    def plan_terminal(self, distance: float, alpha: float) -> float:
        """The terminal epigraph variable of a plan: ``t = min(‖x_N − x̄‖∞, α)`` when the
        plan exceeds the terminal set by more than the tolerance (the rest is ``ε_T``), else
        ``‖x_N − x̄‖∞`` (the hard problem's)."""
        return distance if distance - alpha <= FEAS_TOL else max(alpha, 0.0)

    def initial(self, w0: np.ndarray, excess: np.ndarray, distance: float, alpha: float
                ) -> None:
        """The slacks of the initial guess ``w0`` (in place): its plan's excess (no
        tolerance: the SQP starts from a point that keeps every row)."""
        w0[self.idx[:self.q]] = (np.maximum(0.0, np.max(excess, axis=0)) if excess.size
                                 else 0.0)
        w0[self.idx[-1]] = max(0.0, distance - alpha)
