"""The paper's reference in the FHOCP ``eq:optimization``: a set-point given with every solve.

The :class:`~controllers.ocp.reference.Reference` of the paper's robust MPC (``eq:mpc``): the
reference ``(x̄, ū)`` of the requested output and the terminal radius ``α(ȳ)`` (``eq:def-alpha``) are
parameters of each solve (:class:`Setpoint`), the cost ``eq:optimization-cost`` is::

    Σ_{i<N} ‖x_i − x̄‖²_Q + ‖u_i − ū‖²_R + s ‖x_N − x̄‖²_∞  [+ Σ_{i<N} ‖u_i − u_{i−1}‖²_S]

with the terminal set ``‖x_N − x̄‖∞ ≤ α`` (``eq:terminal_constraint``), and ``p = (x̂, x̄,
ū[, u_{−1}])``. Both formulations: single shooting (:mod:`controllers.ocp.
nlp_single_shooting`) and the plain multiple-shooting baseline; the layout of ``w`` and
``g`` and the warm start are :class:`controllers.ocp.fhocp_layout.FHOCPLayout`'s.

Besides the protocol, what the paper's controllers ask of their problem: a given plan
evaluated (:meth:`FixedSetpoint.evaluate`, the fallback candidate of ``eq:mpc``'s proof), its
cost (:meth:`FixedSetpoint.cost`) and the reference governor's feasibility test
(:meth:`FixedSetpoint.assess`).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.ocp.fhocp_layout import FHOCPLayout
from controllers.ocp.fhocp_result import FHOCPResult, plan_residuals, set_residuals
from controllers.ocp.input_rate import du_cost
from controllers.ocp.reference import ServesOne
from controllers.ocp.solve_status import SolveStatus

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["FixedSetpoint", "Setpoint"]


@dataclass(frozen=True)
class Setpoint:
    """One solve's request of the paper's law: the set-point ``(x̄, ū)``, the terminal
    radius α, the initial inputs (``None``: the previous solution shifted with ``ū``
    appended when ``warm``, else ``ū``) and ``u_{−1}``."""

    x_bar: np.ndarray
    u_bar: np.ndarray
    alpha: float
    u_init: np.ndarray | None
    warm: bool
    u_prev: np.ndarray


class FixedSetpoint(ServesOne):
    """The paper's law's reference (module docstring): a
    :class:`~controllers.ocp.reference.Reference` with the set-point a parameter of each
    solve; the FHOCP's default."""

    name = "paper"
    formulations = ("single-shooting", "multiple-shooting")
    sqp_overrides = MappingProxyType({})

    def attach(self, fhocp: FHOCP, data: Any) -> None:
        self._refuse_another(fhocp)
        self.fhocp = fhocp
        self.layout = FHOCPLayout(fhocp, fhocp.formulation == "single-shooting")
        lay = self.layout
        self.nw, self.iu, self.it, self.ix, self.ng = lay.nw, lay.iu, lay.it, lay.ix, lay.ng
        self.npar = 2 * fhocp.n + fhocp.m + (fhocp.m if fhocp.has_du else 0)

    def kernel_terms(self) -> dict[str, Any]:
        return {}

    def nlp(self, kernel: Any) -> Any:
        from controllers.ocp.nlp_single_shooting import SingleShootingNLP

        return SingleShootingNLP(self._fh, kernel)

    # -- one solve -----------------------------------------------------------------------
    def request(self, x_bar: np.ndarray, u_bar: np.ndarray, alpha: float,
                u_init: np.ndarray | None = None, warm: bool = True,
                u_prev: np.ndarray | None = None) -> Setpoint:
        """The request of :meth:`controllers.ocp.fhocp.FHOCP.solve`: ``eq:optimization`` for
        the set-point ``(x̄, ū)`` with the terminal radius α.

        Parameters
        ----------
        u_init : (N, m) array, optional
            Initial guess of the inputs; default: the previous solution shifted by one stage
            with ``ū`` appended (and its multipliers, shifted too) when ``warm``, else ``ū``.
        u_prev : (m,) array, optional
            The input applied at the previous step, ``u_{−1}`` of the input-rate term
            (ignored without one); ``None``: ``ū`` (the first step).
        """
        fh = self._fh
        x_bar = np.asarray(x_bar, dtype=float).reshape(fh.n)
        u_bar = np.asarray(u_bar, dtype=float).reshape(fh.m)
        return Setpoint(x_bar, u_bar, float(alpha), u_init, warm, self.u_prev(u_prev, u_bar))

    def write(self, ins: dict[str, np.ndarray], x_hat: np.ndarray, e_o: float,
              request: Setpoint) -> None:
        fh = self._fh
        self.layout.write(ins, fh.tightened_bounds(e_o), x_hat, request.x_bar,
                          request.u_bar, request.alpha, request.u_init,
                          fh.warm_start if request.warm else None, fh.warm_duals,
                          fh.rollout, request.u_prev if fh.has_du else None, fh.prefix,
                          fh.start_slacks if fh.softening else None, fh.operator)

    def check_answer(self, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray, e_o: float,
                     request: Setpoint, status: str) -> FHOCPResult:
        """The kernel's plain rollout, cross-checked against numpy when loaded, in one call;
        or numpy's. IPOPT may overshoot a bound by ~1e-9: u is clipped."""
        fh = self._fh
        t = float(wopt[self.it])
        if fh.kernel is not None:
            u, x, out, _ = fh.kernel.assess_w(wopt, pv, fh.tightened_bounds(e_o),
                                              request.alpha)
            res = FHOCPResult(u=u, x=x, cost=out.cost, status=status, success=False, t=t,
                              defect=out.defect)
            set_residuals(res, out, request.alpha, fh.softening)
            return res
        u = np.clip(wopt[self.iu], -1.0, 1.0)
        x = fh.simulate(x_hat, u)
        bounds = fh.tightened_bounds(e_o)
        res = FHOCPResult(u=u, x=x, cost=self.plan_cost(x, u, request.x_bar, request.u_bar,
                                                        bounds, request.alpha, request.u_prev),
                          status=status, success=False, t=t,
                          defect=float(np.max(np.abs(fh.solver_trajectory(wopt, pv) - x))))
        self.residuals(res, x, bounds, request.x_bar, request.alpha, fh.softening)
        return res

    def fallback(self, x_hat: np.ndarray, e_o: float, request: Setpoint,
                 status: str) -> FHOCPResult:
        res = self.evaluate(x_hat, np.tile(request.u_bar, (self._fh.N, 1)), request.x_bar,
                            request.u_bar, e_o, request.alpha, request.u_prev)
        res.status = status
        return res

    # -- what the paper's controllers ask ------------------------------------------------
    def evaluate(self, x_hat: np.ndarray, u_seq: np.ndarray, x_bar: np.ndarray,
                 u_bar: np.ndarray, e_o: float, alpha: float,
                 u_prev: np.ndarray | None = None) -> FHOCPResult:
        """A given input sequence evaluated (cost, trajectory, residuals) without solving;
        ``u_prev``: ``u_{−1}`` of the input-rate term (see :meth:`cost`)."""
        fh = self._fh
        u_seq = np.clip(np.asarray(u_seq, dtype=float), -1.0, 1.0)
        if fh.kernel is not None:   # the same check in one compiled call
            x, out = fh.kernel.assess(x_hat, u_seq, x_bar, u_bar, fh.tightened_bounds(e_o),
                                      alpha, self.u_prev(u_prev, u_bar))
            res = FHOCPResult(u=u_seq, x=x, cost=out.cost, status=SolveStatus.CANDIDATE,
                              success=False, t=out.terminal_distance)
            set_residuals(res, out, alpha)
            return res
        x = fh.simulate(np.asarray(x_hat, dtype=float), u_seq)
        bounds = fh.tightened_bounds(e_o)
        res = FHOCPResult(u=u_seq, x=x, cost=self.plan_cost(x, u_seq, x_bar, u_bar, bounds,
                                                            alpha, u_prev),
                          status=SolveStatus.CANDIDATE, success=False,
                          t=float(np.max(np.abs(x[-1] - x_bar))))
        self.residuals(res, x, bounds, x_bar, alpha)
        return res

    def assess(self, x_hat: np.ndarray, u_seq: np.ndarray, x_bar: np.ndarray, e_o: float,
               alpha: float) -> tuple[float, float]:
        """``(max output violation at i = 1 … N−1, ‖x_N − x̄‖∞)`` of ``u_seq`` (N, m) from
        ``x̂`` (the reference governor's feasibility test; the i = 0 row only involves
        ``x̂``)."""
        fh = self._fh
        bounds = fh.tightened_bounds(e_o)
        if fh.kernel is not None:
            _, out = fh.kernel.assess(x_hat, u_seq, x_bar, np.zeros(fh.m), bounds, alpha)
            return out.violation_rows, out.terminal_distance
        x = fh.rollout(x_hat, u_seq)
        viol = float(np.max(x[1: fh.N] @ fh.LUo.T - bounds[1:])) if fh.N > 1 else -np.inf
        return viol, float(np.max(np.abs(x[fh.N] - x_bar)))

    def cost(self, x: np.ndarray, u: np.ndarray, x_bar: np.ndarray, u_bar: np.ndarray,
             t: float | None = None, u_prev: np.ndarray | None = None) -> float:
        """Cost ``eq:optimization-cost`` (``t`` defaults to ``‖x_N − x̄‖∞``), plus the
        input-rate term when the problem has one, with ``u_{−1} = u_prev`` (``None``: ``ū``,
        the first step's convention: the sequence ``ū`` repeated then pays nothing for it)."""
        fh = self._fh
        dx = x[: fh.N] - x_bar
        du = u - u_bar
        tN = float(np.max(np.abs(x[fh.N] - x_bar))) if t is None else t
        J = float(np.vdot(dx @ fh.Q, dx) + np.vdot(du @ fh.R, du) + fh.s * tN ** 2)
        if fh.has_du:
            J += du_cost(u, self.u_prev(u_prev, u_bar), fh.du_weight)
        return J

    def residuals(self, res: FHOCPResult, x: np.ndarray, bounds: np.ndarray,
                  x_bar: np.ndarray, alpha: float, soft: bool = False) -> None:
        """The output rows' (right-hand sides ``bounds``, N×q: :meth:`~controllers.ocp.
        fhocp.FHOCP.tightened_bounds`), input box's and terminal set's violations of
        ``(res.u, x)``, and the active rows, into ``res``
        (:func:`~controllers.ocp.fhocp_result.plan_residuals` around ``x̄``)."""
        plan_residuals(res, x, self._fh.LUo, bounds, x_bar, alpha, soft)

    def plan_cost(self, x: np.ndarray, u: np.ndarray, x_bar: np.ndarray, u_bar: np.ndarray,
                  bounds: np.ndarray, alpha: float, u_prev: np.ndarray | None = None
                  ) -> float:
        """The cost of a plan ``(x, u)`` (:meth:`cost` with ``t = ‖x_N − x̄‖∞``); with
        softened rows (:mod:`controllers.ocp.soft`) ``t = min(‖x_N − x̄‖∞, α)`` and the
        penalty of the plan's smallest slacks (right-hand sides ``bounds``, N×q)."""
        fh = self._fh
        dN = float(np.max(np.abs(x[fh.N] - x_bar)))
        sl = fh.soft_design
        if sl is None:
            return self.cost(x, u, x_bar, u_bar, dN, u_prev)
        eps = sl.of_plan(x[1:fh.N] @ fh.LUo.T - bounds[1:], dN, alpha)
        return (self.cost(x, u, x_bar, u_bar, sl.plan_terminal(dN, alpha), u_prev)
                + sl.penalty(eps))

    def u_prev(self, u_prev: np.ndarray | None, u_bar: np.ndarray) -> np.ndarray:
        """``u_{−1}`` (m,): ``u_prev``, else ``ū`` (before any input was applied)."""
        return np.asarray(u_bar if u_prev is None else u_prev,
                          dtype=float).reshape(self._fh.m)
