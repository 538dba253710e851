"""The paper's MPC law ``eq:mpc``: the FHOCP each step, with the fallback of the proof.

:class:`PaperMPC` solves :class:`~controllers.ocp.fhocp.FHOCP` every step from the candidate of
the proof of ``th:feasibility-stability`` (the previous sequence shifted by one stage with
``ū`` appended) and applies that candidate when a solve fails; each step's
:class:`~controllers.laws.base.StepRecord` says what happened
(:func:`~controllers.laws.base.solver_summary` sums them up).

With an input-rate term in the cost (``FHOCP(du_weight=…)``, :mod:`controllers.ocp.input_rate`)
the controller hands the FHOCP the input it applied at the previous step as ``u_{−1}`` (``ū``
before the first), and the candidate's cost, which a capped iterate must not exceed to be
applied, includes the term with the same ``u_{−1}``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from controllers.laws.base import StepRecord, solver_summary
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.solver_settings import FEAS_TOL

__all__ = ["PaperMPC"]


class PaperMPC:
    """The MPC law ``eq:mpc`` with the fallback of the proof of ``th:feasibility-stability``.

    At each step the FHOCP is solved from the candidate of the proof (the previous sequence
    shifted by one stage with ``ū`` appended). When the solve fails (solver failure,
    infeasibility, iteration or time limit, or a failed residual check) that candidate is
    applied instead, and the next step shifts it again. Before any successful solve the
    candidate is ``ū`` repeated.

    Suboptimal MPC (``accept_suboptimal``, default on): when the solve stops at the
    iteration cap with an iterate that passes every residual check (feasible) and costs no
    more than the candidate, that iterate is applied instead of the candidate (Scokaert,
    Mayne & Rawlings 1999: feasibility and the candidate's cost decrease are what the proof of
    ``th:feasibility-stability`` uses). Counted as ``suboptimal_steps``, not as fallbacks.

    Parameters
    ----------
    fhocp : FHOCP
        The problem (set up on first use).
    accept_suboptimal : bool
        Apply feasible capped iterates (see above); ``False``: only converged solves.
    """

    def __init__(self, fhocp: FHOCP, accept_suboptimal: bool = True) -> None:
        self.fhocp = fhocp
        self.accept_suboptimal = bool(accept_suboptimal)
        self.reset()

    def reset(self) -> None:
        """Forget the set-point, the plan and the records (a new run)."""
        self.x_bar: np.ndarray | None = None
        self.u_bar: np.ndarray | None = None
        self.alpha: float = float("nan")
        self.plan: np.ndarray | None = None
        self.records: list[StepRecord] = []
        #: the input applied at the previous step (``u_{−1}`` of the input-rate term)
        self.u_prev: np.ndarray | None = None

    def set_reference(self, x_bar: np.ndarray, u_bar: np.ndarray, alpha: float) -> None:
        """Set-point data ``(x̄, ū, α)`` (``eq:def-alpha``); call again when ``ȳ`` changes."""
        self.x_bar = np.asarray(x_bar, dtype=float)
        self.u_bar = np.asarray(u_bar, dtype=float)
        self.alpha = float(alpha)

    def candidate(self) -> np.ndarray:
        """The shifted previous sequence with ``ū`` appended (``ū`` repeated at first)."""
        assert self.u_bar is not None
        if self.plan is None:
            return np.tile(self.u_bar, (self.fhocp.N, 1))
        return np.vstack([self.plan[1:], self.u_bar])

    def make_step(self, x_hat: np.ndarray, e_o: float,
                  candidate: np.ndarray | None = None) -> StepRecord:
        """Compute ``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``), with the fallback.

        ``candidate`` (N, m), optional: a sequence known to be feasible (the reference
        governor's, :mod:`controllers.laws.paper.governor`); it is the initial guess of the
        solve and the fallback, in place of the shifted previous plan.
        """
        if self.x_bar is None or self.u_bar is None:
            raise RuntimeError("set_reference() must be called before make_step()")
        prefix = self.fhocp.prefix   # the inputs already applied (dead times beyond the least)
        cand = prefix.impose(self.candidate() if candidate is None
                             else np.asarray(candidate, dtype=float))
        # the FHOCP warm-starts from its own last iterate shifted by one stage: the candidate
        # itself after a success, the partially converged iterate after a failure
        t0 = time.perf_counter()
        try:
            res = self.fhocp.solve(x_hat, e_o, self.x_bar, self.u_bar, self.alpha,
                                   u_init=candidate, u_prev=self.u_prev)
        except Exception as exc:
            res = self.fhocp.reference.evaluate(x_hat, cand, self.x_bar, self.u_bar, e_o,
                                          self.alpha, self.u_prev)
            res.status = f"solver_error: {type(exc).__name__}: {exc}"[:200]
            res.solve_time = time.perf_counter() - t0
        if res.success:
            self.plan = res.u.copy()
            rec = StepRecord(u=prefix.applied(res.u), result=res, fallback=False)
            rec.x_hat, rec.e_o = np.array(x_hat, dtype=float), float(e_o)
            self.records.append(rec)
            self.u_prev = rec.u
            return rec
        chk = self.fhocp.reference.evaluate(x_hat, cand, self.x_bar, self.u_bar, e_o, self.alpha,
                                      self.u_prev)
        feasible = chk.constraint_violation <= FEAS_TOL and chk.terminal_violation <= FEAS_TOL
        if self.accept_suboptimal and res.feasible and (
                not feasible or res.cost <= chk.cost):
            # suboptimal MPC: a feasible iterate no costlier than the candidate keeps the
            # proof's arguments (feasibility, and the cost decrease the candidate gives)
            self.plan = res.u.copy()
            rec = StepRecord(u=prefix.applied(res.u), result=res, fallback=False, suboptimal=True,
                             x_hat=np.array(x_hat, dtype=float), e_o=float(e_o))
        else:
            self.plan = cand
            rec = StepRecord(u=np.clip(prefix.applied(cand), -1.0, 1.0), result=res, fallback=True,
                             candidate_feasible=bool(feasible),
                             x_hat=np.array(x_hat, dtype=float), e_o=float(e_o))
        self.records.append(rec)
        self.u_prev = rec.u
        return rec

    def summary(self) -> dict[str, Any]:
        """Solver statistics over the steps so far."""
        return solver_summary(self.records)
