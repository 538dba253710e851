"""One solve of ``eq:optimization`` (:class:`FHOCPResult`) and the one judge of every answer
(:func:`judge`, with the solver's statistics read by :func:`solver_stats`, the residuals of
the compiled check by :func:`set_residuals`): what :mod:`controllers.ocp.fhocp` returns for
every law (:mod:`controllers.laws.paper.reference`,
:mod:`controllers.laws.tracking.reference`) and what the kernel's self-test
(:mod:`controllers.ocp.nlp_single_shooting`) compares, in a module of its own so that none of
them imports another."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.ocp.solve_status import SOLVER_SUCCEEDED, SolveStatus
from controllers.ocp.solver_settings import DEFECT_TOL, FEAS_TOL

__all__ = ["FHOCPResult", "judge", "keeps_warm_start", "plan_residuals", "route_softened",
           "set_residuals", "solver_stats"]


@dataclass
class FHOCPResult:
    """One solve of ``eq:optimization``.

    Attributes
    ----------
    u : (N, m) array
        Optimal (or last) input sequence, normalised.
    x : (N + 1, n) array
        Its state trajectory, rolled out with numpy from ``x̂``.
    cost : float
        Cost ``eq:optimization-cost`` of ``(x, u)`` evaluated with numpy.
    status : str
        A :class:`~controllers.ocp.solve_status.SolveStatus` (``"optimal"``, ``"infeasible_x0"``,
        ``"residual_check_failed"``, …) or the solver's own return status when it failed.
    success : bool
        Solver success AND residual checks passed.
    iterations : int
    solve_time : float
        Wall time of the solve [s].
    constraint_violation : float
        ``max(0, max_i,j (L(U_o x_i + b_o) + w_L − h + a_i ê_o + b_i)_j)`` over ``i = 0 … N−1``,
        together with input-box violations.
    terminal_violation : float
        ``max(0, ‖x_N − x̄‖∞ − α)``.
    defect : float
        ``max ‖x_solver − x_numpy‖∞`` (dynamics defect for multiple shooting; casadi-vs-numpy
        model check for single shooting).
    active : int
        Number of output / terminal / input constraints active (within 1e-6) at the answer.
    feasible : bool
        The answer satisfies every constraint (a solver that stopped early may still return
        a feasible, suboptimal sequence); with softened rows (:mod:`controllers.ocp.soft`)
        every hard one: the input box (the softened rows' excess is :attr:`softened`).
    softened : float
        With softened rows: the plan's largest excess over a softened row (output rows
        ``i = 0 … N−1``, the terminal set, ``Y_s``), 0 when it keeps them all; the
        residuals above then hold the input box's only. 0 for the hard problem.
    """

    u: np.ndarray
    x: np.ndarray
    cost: float
    status: str
    success: bool
    iterations: int = 0
    solve_time: float = 0.0
    constraint_violation: float = 0.0
    terminal_violation: float = 0.0
    defect: float = 0.0
    active: int = 0
    t: float = 0.0
    feasible: bool = False
    softened: float = 0.0
    lam_x: np.ndarray | None = field(default=None, repr=False)
    lam_g: np.ndarray | None = field(default=None, repr=False)
    #: the tracking law's artificial steady input and state
    #: (:mod:`controllers.laws.tracking.reference`)
    u_s: np.ndarray | None = None
    x_s: np.ndarray | None = field(default=None, repr=False)


def plan_residuals(res: FHOCPResult, x: np.ndarray, LUo: np.ndarray, bounds: np.ndarray,
                   x_ref: np.ndarray, alpha: float, soft: bool = False) -> float:
    """The residuals of the plan ``(res.u, x)`` (``x_0 … x_N``) into ``res``: the output
    rows' ``L U_o x_i ≤ bounds_i`` (``i = 0 … N−1``, ``eq:optimization-constraint``) and
    the input box's violation, the terminal set's ``‖x_N − x_ref‖∞ ≤ α`` and the rows
    active within 1e-6; returns ``‖x_N − x_ref‖∞``. Every law's numpy answer check.
    ``soft``: the output rows and the terminal set are softened (their excess into
    ``res.softened``, :func:`route_softened`)."""
    N = bounds.shape[0]
    lhs = x[:N] @ LUo.T
    res.constraint_violation = max(0.0, float(np.max(lhs - bounds)),
                                   float(np.max(np.abs(res.u))) - 1.0)
    dN = float(np.max(np.abs(x[N] - x_ref)))
    res.terminal_violation = max(0.0, dN - alpha)
    res.active = (int(np.sum(lhs[1:] - bounds[1:] > -1e-6)) + int(dN - alpha > -1e-6)
                  + int(np.sum(np.abs(res.u) > 1 - 1e-6)))
    if soft:
        route_softened(res, float(np.max(np.abs(res.u))) - 1.0)
    return dN


def set_residuals(res: FHOCPResult, out: Any, alpha: float, soft: bool = False) -> None:
    """:func:`plan_residuals` from the compiled check's
    :class:`~controllers.kernel.kernel_abi.Assessment`
    (:meth:`controllers.kernel.kernel_lib.Workspace.
    assess`)."""
    res.constraint_violation = max(0.0, out.violation_first, out.violation_rows,
                                   out.u_max - 1.0)
    res.terminal_violation = max(0.0, out.terminal_distance - alpha)
    res.active = int(out.active)
    if soft:
        route_softened(res, out.u_max - 1.0)


def route_softened(res: FHOCPResult, box: float) -> None:
    """The softened problem's residuals: the output rows' and the terminal set's excess
    becomes ``res.softened`` (a price paid in the cost, not a failure), the residuals
    that judge an answer keep the input box's violation ``box`` only."""
    res.softened = max(res.softened, res.constraint_violation, res.terminal_violation)
    res.constraint_violation = max(0.0, box)
    res.terminal_violation = 0.0


def solver_stats(buffer: Any) -> dict[str, Any]:
    """The statistics of the solve just run (``return_status``, ``success``, ``iter_count``),
    with the time budget's stop named :attr:`~SolveStatus.TIME_BUDGET_EXCEEDED` and casadi
    3.8 ``sqpmethod``'s missing statistics after a failed line search
    :attr:`~SolveStatus.STATS_UNAVAILABLE`."""
    try:
        stats = buffer.stats()
    except RuntimeError:
        return {"return_status": SolveStatus.STATS_UNAVAILABLE, "success": False}
    if stats.get("return_status") == "User_Requested_Stop":
        stats = {**stats, "return_status": SolveStatus.TIME_BUDGET_EXCEEDED, "success": False}
    return stats


def judge(res: FHOCPResult, stats: dict[str, Any], w: np.ndarray) -> None:
    """The answer check of every FHOCP: accept the solver's answer ``w`` only when the solver
    succeeded AND the residuals measured apart from it (``res``: rollout, constraints,
    terminal set, defect) are within :data:`~controllers.ocp.solver_settings.FEAS_TOL` and
    :data:`~controllers.ocp.solver_settings.DEFECT_TOL`; sets ``feasible``, ``success``,
    ``iterations`` and the :class:`~controllers.ocp.solve_status.SolveStatus` (``res.status``
    holds the solver's status on entry)."""
    ok_status = bool(stats.get("success", False))
    res.iterations = int(stats.get("iter_count", 0))
    res.feasible = bool(np.all(np.isfinite(w)) and res.constraint_violation <= FEAS_TOL
                        and res.terminal_violation <= FEAS_TOL and res.defect <= DEFECT_TOL)
    res.success = ok_status and res.feasible
    if res.success and res.status == SOLVER_SUCCEEDED:
        res.status = SolveStatus.OPTIMAL
    elif ok_status and not res.success:
        # (the two copies before this function called such an answer "optimal")
        res.status = SolveStatus.RESIDUAL_CHECK_FAILED
    elif res.status == SOLVER_SUCCEEDED:
        # sqpmethod aborted (e.g. a failed QP) and left the previous solve's status
        res.status = SolveStatus.SOLVER_ABORTED


def keeps_warm_start(res: FHOCPResult, w: np.ndarray) -> bool:
    """Whether the next solve starts from this one's primal-dual answer: after a success, and
    after a failure (time budget, iteration cap) whose last iterate is finite: the
    optimisation then continues across steps."""
    return res.success or bool(
        np.all(np.isfinite(w)) and res.lam_g is not None and np.all(np.isfinite(res.lam_g))
        and res.lam_x is not None and np.all(np.isfinite(res.lam_x)))
