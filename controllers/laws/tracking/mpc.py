"""The tracking MPC law: the tracking FHOCP each step, with the candidate as fallback.

:class:`TrackingMPC` solves the FHOCP with the tracking law
(:class:`~controllers.laws.tracking.reference.ArtificialSteadyState`) every step for
the target ``r = ȳ − d̂`` from the candidate of the recursive-feasibility argument (the
previous plan shifted by one stage with the artificial steady input ``u_s`` appended, and the
same ``u_s``), and applies that candidate when a solve fails. Unlike the paper's law
(:class:`controllers.laws.paper.mpc.PaperMPC`) no set-point is ever refused: ``r`` enters the
cost only, so the candidate stays feasible whatever ``r`` does (docs: design/tracking.md,
claim 1). :class:`DisturbanceFilter` is the offset-free estimate ``d̂``.
"""

from __future__ import annotations

import time

import numpy as np

from controllers.laws.base import StepRecord
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.fhocp_result import FHOCPResult
from controllers.ocp.solver_settings import FEAS_TOL

__all__ = ["DisturbanceFilter", "TrackingMPC"]


class DisturbanceFilter:
    """Output-disturbance estimate ``d̂_{k+1} = d̂_k + β (y_k − g(x̂_k) − d̂_k)`` (offset-free
    MPC with an output disturbance model; ``0 < β ≤ 1``, ``d̂_0 = 0``)."""

    def __init__(self, beta: float, p: int) -> None:
        if not 0 < beta <= 1:
            raise ValueError(f"the disturbance filter's beta must be in (0, 1], got {beta!r}")
        self.beta = float(beta)
        self.d_hat = np.zeros(p)

    def reset(self) -> None:
        self.d_hat = np.zeros_like(self.d_hat)

    def update(self, y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
        """Advance with the measured ``y`` and the model output ``g(x̂)``; returns ``d̂``."""
        self.d_hat = self.d_hat + self.beta * (np.asarray(y, dtype=float) - y_hat - self.d_hat)
        return self.d_hat


class TrackingMPC:
    """The tracking MPC law with the candidate fallback (module docstring).

    Parameters
    ----------
    fhocp : controllers.ocp.fhocp.FHOCP
        With the tracking law (:class:`~controllers.laws.tracking.reference.ArtificialSteadyState`).
    accept_suboptimal : bool
        Apply a feasible iterate of a capped solve that costs no more than the candidate
        (suboptimal MPC, as :class:`controllers.laws.paper.mpc.PaperMPC`).
    """

    def __init__(self, fhocp: FHOCP, accept_suboptimal: bool = True) -> None:
        self.fhocp = fhocp
        self.accept_suboptimal = bool(accept_suboptimal)
        #: the design's hypotheses
        #: (:func:`controllers.laws.tracking.checks.tracking_hypotheses`)
        self.hypotheses: dict | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the steady state, the plan and the records (a new run)."""
        self.u_s: np.ndarray | None = None
        self.x_s: np.ndarray | None = None
        self.plan: np.ndarray | None = None
        self.records: list[StepRecord] = []
        self.u_prev: np.ndarray | None = None
        #: the next solve's initial guess (u, u_s, x_s): the last iterate shifted, so that
        #: after a failed solve the optimisation continues where it stopped
        self._guess: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def start(self, u_s: np.ndarray, x_s: np.ndarray) -> None:
        """The initial artificial steady state (e.g. the equilibrium ``x̂_0`` starts at)."""
        self.u_s = np.clip(np.asarray(u_s, dtype=float), -1.0, 1.0)
        self.x_s = np.asarray(x_s, dtype=float)
        self.plan = None
        self._guess = None

    def candidate(self) -> np.ndarray:
        """The shifted previous plan with ``u_s`` appended (``u_s`` repeated at first)."""
        assert self.u_s is not None
        if self.plan is None:
            return np.tile(self.u_s, (self.fhocp.N, 1))
        return np.vstack([self.plan[1:], self.u_s])

    def make_step(self, x_hat: np.ndarray, e_o: float, r: np.ndarray) -> StepRecord:
        """``u_k`` for the target ``r = ȳ − d̂`` (normalised), with the fallback."""
        if self.u_s is None or self.x_s is None:
            raise RuntimeError("start() must be called before make_step()")
        fh = self.fhocp
        cand = fh.prefix.impose(self.candidate())   # the inputs already applied, as they were
        up = self.u_prev if self.u_prev is not None else self.u_s
        g_u, g_us, g_xs = self._guess or (cand, self.u_s, self.x_s)
        t0 = time.perf_counter()
        try:
            res = fh.solve(x_hat, e_o, r, g_u, g_us, g_xs, up, us_centre=self.u_s)
        except Exception as exc:   # a solver crash: the candidate, as a failed solve
            res = fh.reference.evaluate(x_hat, cand, self.u_s, e_o, r, self.x_s, up)
            res.status = f"solver_error: {type(exc).__name__}: {exc}"[:200]
            res.solve_time = time.perf_counter() - t0
        use = res.success
        fallback = False
        feasible = True
        if not use:
            chk = fh.reference.evaluate(x_hat, cand, self.u_s, e_o, r, self.x_s, up)
            feasible = (chk.constraint_violation <= FEAS_TOL
                        and chk.terminal_violation <= FEAS_TOL)
            use = self.accept_suboptimal and res.feasible and (
                not feasible or res.cost <= chk.cost)
            fallback = not use
        rec = self._record(res, x_hat, e_o, use, fallback, feasible, cand)
        self._guess = None
        if res.u_s is not None and res.x_s is not None and np.all(np.isfinite(res.x_s)):
            self._guess = (np.vstack([res.u[1:], res.u_s]), res.u_s, res.x_s)
        self.records.append(rec)
        self.u_prev = rec.u
        return rec

    def _record(self, res: FHOCPResult, x_hat: np.ndarray, e_o: float, use: bool,
                fallback: bool, feasible: bool, cand: np.ndarray) -> StepRecord:
        if use:
            assert res.u_s is not None and res.x_s is not None
            self.plan, self.u_s, self.x_s = res.u.copy(), res.u_s.copy(), res.x_s.copy()
            u = self.fhocp.prefix.applied(res.u)
        else:
            self.plan = cand
            u = np.clip(self.fhocp.prefix.applied(cand), -1.0, 1.0)
        return StepRecord(u=u, result=res, fallback=fallback,
                          candidate_feasible=bool(feasible),
                          suboptimal=bool(use and not res.success),
                          x_hat=np.array(x_hat, dtype=float), e_o=float(e_o))
