"""One solve of the FHOCP ``eq:optimization``: what :class:`controllers.ocp.fhocp.FHOCP` does
each step (:class:`Solving`, its solving half; :mod:`controllers.ocp.fhocp` declares the
problem and builds the solver).

The tightened bounds of ``ê_o`` (``eq:optimization-constraint``), the ``i = 0`` row (it
involves ``x̂`` only), the hard phase and, for a softened FHOCP whose hard problem has no
answer, the softened phase (:mod:`controllers.ocp.soft`), the solver within its optional time
budget, the reference's independent answer check, the one judge
(:func:`controllers.ocp.fhocp_result.judge`) and the warm start.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from controllers import gru
from controllers.ocp.casadi_callbacks import quiet_stdout
from controllers.ocp.fhocp_result import FHOCPResult, judge, keeps_warm_start, solver_stats
from controllers.ocp.solve_status import SOFTEN_AFTER, SolveStatus
from controllers.ocp.solver_settings import FEAS_TOL

__all__ = ["Solving"]


class Solving:
    """The solving half of :class:`~controllers.ocp.fhocp.FHOCP` (its attributes: the
    problem's data, the reference, the solver and its buffers)."""

    def tightened_bounds(self, e_o: float) -> np.ndarray:
        """Right-hand sides ``h − a_i ê_o − b_i − w_L − L b_o`` for ``i = 0 … N−1`` (N×q,
        read-only: the last one is kept, ``ê_o`` settles at its fixed point), minus ``L d``
        of :meth:`set_output_shift`; ``h − δ`` under the operator's limits
        (:attr:`narrowing`, ``eq:operator-rows``)."""
        e_o = float(e_o)
        if self._bounds_eo != e_o:
            h = self.h if self._narrowing is None else self.h - self._narrowing
            bounds = h - self.a * e_o - self.b - self.w_L - self.Lbo
            if self.output_shift is not None:
                bounds = bounds - self.output_shift
            bounds.flags.writeable = False
            self._bounds_eo, self._bounds = e_o, bounds
        return self._bounds

    def set_output_shift(self, d: np.ndarray | None) -> None:
        """Constrain ``y + d`` instead of the model's ``y``: every output row
        ``L (U_o x_i + b_o + d) ≤ …`` (and the reference's rows on steady outputs; the tracking
        law's uncertified mode's ``d = d̂``, the filtered output mismatch, so that the
        measured tightening is around the output the plant will show); ``None`` restores the
        rows as declared."""
        self.output_shift = (None if d is None
                             else self.L @ np.asarray(d, dtype=float).reshape(self.p))
        self._bounds_eo = float("nan")

    def start_slacks(self, w0: np.ndarray, pv: np.ndarray, x: np.ndarray, x_ref: np.ndarray,
                     bounds: np.ndarray, alpha: float) -> float:
        """The initial guess ``w0``'s slacks (softened rows, in place): those of its plan
        (states ``x`` towards ``x_ref``; ``bounds`` N×q, the tracking law's with ``Y_s``'s
        row last), so that the SQP starts from a point that keeps every row; returns the
        plan's terminal gap. The compiled kernel's (its own rollout and reference, the
        exported controller's numbers; ``x`` unused) when there is one, else numpy's."""
        assert self.slacks is not None, "start_slacks of a hard FHOCP"
        if self.kernel is not None:
            return self.kernel.plan_slacks(w0, pv, bounds, alpha)
        N = self.N
        excess = x[1:N] @ self.LUo.T - bounds[1:N]
        if bounds.shape[0] > N:
            excess = np.vstack([excess, self.LUo @ x_ref - bounds[N]])
        gap = float(np.max(np.abs(x[N] - x_ref)))
        self.slacks.initial(w0, excess, gap, alpha)
        return gap

    def rollout(self, x_hat: np.ndarray, u_seq: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` of ``eq:gru`` from ``x̂`` under ``u_seq`` (N, m)."""
        if self._solver is None:
            self.setup()
        if self.kernel is not None:
            return self.simulate(x_hat, u_seq)
        if self.formulation == "single-shooting":
            return self._shoot.rollout(x_hat, u_seq, derivatives=False).x
        return gru.simulate(self.params, x_hat, u_seq)[0]

    def check_x0(self, x_hat: np.ndarray, e_o: float) -> float:
        """Violation of the ``i = 0`` constraint at ``x̂`` (≤ 0 when satisfied)."""
        return float(np.max(self.LUo @ x_hat - self.tightened_bounds(e_o)[0]))

    def x0_infeasible(self, x_hat: np.ndarray, e_o: float) -> bool:
        """The ``i = 0`` row, which involves ``x̂`` only, fails: the problem is infeasible
        and no solver is called. The test allows :data:`~controllers.ocp.solver_settings.
        FEAS_TOL`, as the answer check does: an accepted answer may exceed a row by that
        much, and the next ``x̂`` (the model's ``x_1`` under zero observer gains) inherits
        it."""
        return self.check_x0(x_hat, e_o) > FEAS_TOL

    def solve(self, x_hat: np.ndarray, e_o: float, *args: Any, **kwargs: Any) -> FHOCPResult:
        """Solve ``eq:optimization`` at ``x̂`` with ``ê_o`` for the reference's request of
        ``args``, ``kwargs``
        (:meth:`Reference.request <controllers.ocp.reference.Reference.request>`): the paper's
        ``(x̄, ū, α[, u_init, warm, u_prev])``
        (:meth:`~controllers.laws.paper.reference.FixedSetpoint.request`), the tracking law's
        ``(r, u_init, us_init, x_s0[, u_prev, warm, us_centre])``
        (:meth:`~controllers.laws.tracking.reference.ArtificialSteadyState.request`). See
        :meth:`solve_request`."""
        return self.solve_request(x_hat, e_o, self.reference.request(*args, **kwargs))

    def solve_request(self, x_hat: np.ndarray, e_o: float, request: Any) -> FHOCPResult:
        """One solve, the same for every law: the ``i = 0`` row checked first (a violated
        one is reported as ``"infeasible_x0"`` with the request's candidate, no solver
        called), the request's parameters, bounds and initial guess written, the solver run
        (within the optional time budget), its answer checked independently by the reference,
        judged (:func:`~controllers.ocp.fhocp_result.judge`) and kept as the next
        warm start. ``solve_time``: the solver and the check (both phases').

        Softened (:mod:`controllers.ocp.soft`): the hard phase first, its slacks fixed at 0;
        when ``x̂`` fails the ``i = 0`` row or the hard phase ends with a status of
        :data:`~controllers.ocp.solve_status.SOFTEN_AFTER`, the softened phase from the same
        guess (and the same warm start)."""
        if self._solver is None:
            self.setup()
        t0 = time.perf_counter()
        x_hat = np.asarray(x_hat, dtype=float).reshape(self.n)
        outside = self.formulation == "single-shooting" and self.x0_infeasible(x_hat, e_o)
        if outside and not self.soft:
            res = self.reference.fallback(x_hat, e_o, request, SolveStatus.INFEASIBLE_X0)
            res.solve_time = time.perf_counter() - t0
            return res
        warm = self.warm_start
        if not (outside or self.always_soften):
            res = self._solve_phase(x_hat, e_o, request, False, t0)
            if not self.soft or res.success or res.status not in SOFTEN_AFTER:
                return res
            self.warm_start = warm   # the softened phase starts where the hard one did
        return self._solve_phase(x_hat, e_o, request, True, t0)

    def _solve_phase(self, x_hat: np.ndarray, e_o: float, request: Any, soften: bool,
                     t0: float) -> FHOCPResult:
        """One solver run of :meth:`solve_request`: the hard problem, or with ``soften`` the
        softened one (its slacks free, their weights on); a hard FHOCP has no phase."""
        buf, trigger, ins, outs = self._buffer
        if self.soft_design is not None:
            self._soften(soften)
        self.reference.write(ins, x_hat, e_o, request)
        if self.soft_design is not None:
            idx = self.soft_design.idx
            ins["ubx"][idx] = np.inf if soften else 0.0
            if not soften:
                ins["x0"][idx] = 0.0
        self._arm_deadline(t0)
        if self._compiled_loop:
            trigger()   # the compiled SQP: no casadi, nothing printed
        else:
            with quiet_stdout():  # qpOASES prints the errors its SQP handles
                trigger()
        stats = solver_stats(buf)
        wopt = outs["x"].copy()
        res = self.reference.check_answer(wopt, ins["p"], x_hat, e_o, request,
                                    str(stats.get("return_status", "unknown")))
        res.solve_time = time.perf_counter() - t0
        res.lam_x, res.lam_g = outs["lam_x"].copy(), outs["lam_g"].copy()
        judge(res, stats, wopt)
        self._keep_warm(res, wopt)
        return res

    def _soften(self, on: bool) -> None:
        """The softened phase's slack weights (``on``) or the hard phase's (none), in the
        numpy problem and the compiled kernel's instance alike."""
        assert self.soft_design is not None
        self.slacks = self.soft_design if on else self._soft_off
        self.softening = on
        if self.kernel is not None:
            self.kernel.set_soft(on)

    def solver_trajectory(self, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` the solver's own formulation gives at ``(w, p)`` (the answer
        check's defect compares a rollout apart from it with these)."""
        return self._xtraj(w, p)

    def _arm_deadline(self, t0: float) -> None:
        """Start the optional wall-time budget of the solve that began at ``t0`` (checked by
        the numpy callbacks of casadi's loops; the kernel's loop has its own)."""
        if self._nlp is not None:
            self._nlp.deadline = t0 + (self.time_budget if self.time_budget is not None
                                       else np.inf)

    def _keep_warm(self, res: FHOCPResult, w: np.ndarray) -> None:
        """Keep ``w`` and its multipliers as the next solve's warm start
        (:func:`controllers.ocp.fhocp_result.keeps_warm_start`)."""
        if keeps_warm_start(res, w):
            self.warm_start = {"w": w, "lam_x": res.lam_x, "lam_g": res.lam_g}

    def reset_warm_start(self) -> None:
        """Forget the previous solution (next solve starts cold)."""
        self.warm_start = None
