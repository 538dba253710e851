"""One status and one judge for both laws (controllers.ocp.solve_status,
controllers.ocp.fhocp_result.judge): the FHOCP with the paper's and with the tracking law report
the same outcomes the same way."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.certification import certificates as certs
from controllers.laws.paper.reference import FixedSetpoint
from controllers.laws.tracking.reference import ArtificialSteadyState
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.fhocp_result import FHOCPResult, judge
from controllers.ocp.solve_status import OTHER_STATUS, SolveStatus, status_code
from controllers.ocp.steady_state import steady_state
from tests.controllers.random_gru import random_gru_model


def _tracking(time_budget: float | None = None, loop: str = "kernel") -> FHOCP:
    cert = certs.compute_certificate(random_gru_model(4, n=6), N=5, gain_scale=0.0,
                                     w_y_bar=0.01)
    return FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1e3, 0.05),
                                  time_budget=time_budget, sqp_options={"loop": loop})


def test_status_codes_are_the_diagnostics_numbers() -> None:
    assert [status_code(s) for s in (SolveStatus.OPTIMAL, "optimal", "infeasible_x0",
                                     "Infeasible_Problem_Detected",
                                     "Maximum_Iterations_Exceeded", "time_budget_exceeded",
                                     "residual_check_failed")] == [0, 0, 1, 2, 3, 3, 4]
    assert status_code("QP_Infeasible") == status_code("candidate") == OTHER_STATUS
    assert f"{SolveStatus.OPTIMAL}" == "optimal"      # written as its value everywhere


@pytest.mark.parametrize(("stats", "violation", "status", "success"), [
    ({"return_status": "Solve_Succeeded", "success": True}, 0.0, "optimal", True),
    ({"return_status": "Solve_Succeeded", "success": True}, 1e-3, "residual_check_failed",
     False),
    ({"return_status": "Solve_Succeeded", "success": False}, 0.0, "solver_aborted", False),
    ({"return_status": "QP_Infeasible", "success": False}, 0.0, "QP_Infeasible", False),
])
def test_one_answer_check(stats: dict, violation: float, status: str, success: bool) -> None:
    res = FHOCPResult(u=np.zeros((2, 1)), x=np.zeros((3, 1)), cost=0.0,
                      status=stats["return_status"], success=False,
                      constraint_violation=violation)
    judge(res, {**stats, "iter_count": 4}, np.zeros(3))
    assert (res.status, res.success, res.iterations) == (status, success, 4)
    assert res.feasible == (violation == 0.0)


@pytest.mark.parametrize("loop", ["kernel", "casadi"])
def test_the_tracking_problem_reports_its_time_budget_as_the_paper_problem(loop: str) -> None:
    """The tracking copy used to report casadi's ``User_Requested_Stop`` (issue 31)."""
    fh = _tracking(time_budget=0.0, loop=loop).setup()
    us = np.full(fh.m, 0.1)
    xs, _, ok = steady_state(fh.params, us, np.zeros(fh.n))
    assert ok
    res = fh.solve(xs, 0.0, np.full(fh.p, 0.3), np.tile(us, (fh.N, 1)), us, xs, warm=False)
    assert res.status == SolveStatus.TIME_BUDGET_EXCEEDED and not res.success


def test_both_laws_are_one_problem_class() -> None:
    """One FHOCP: the tracking law's is no subclass (the i = 0 row, its tolerance, the
    solve procedure are the same code)."""
    assert type(_tracking()) is FHOCP is type(FHOCP.from_certificate(
        certs.compute_certificate(random_gru_model(4, n=6), N=5, w_y_bar=0.01),
        reference=FixedSetpoint()))


def test_a_law_refuses_another_laws_request_by_its_own_arguments() -> None:
    """The paper's set-point ``(x̄, ū, α)`` handed to the tracking law's FHOCP: its request
    names the argument it lacks."""
    with pytest.raises(TypeError, match="x_s0"):
        _tracking().solve(np.zeros(6), 0.0, np.zeros(6), np.zeros(2), 0.1)
