"""How one solve of ``eq:optimization`` ended: the status every FHOCP reports, and its code.

:class:`SolveStatus` names the outcomes the project itself decides (the answer check of
:func:`controllers.ocp.fhocp_result.judge`, the ``i = 0`` test before a solve) and the solver
outcomes the diagnostics count; any other solver return status (``"QP_Infeasible"``,
``"Search_Direction_Becomes_Too_Small"``, …) is kept as the solver's own string. The kernel's
SQP reports casadi ``sqpmethod``'s names (:attr:`controllers.kernel.kernel_abi.SqpStatus.
casadi_name`), so that one mapping serves the compiled loop, ``sqpmethod`` and IPOPT.
:func:`status_code` is the number the controller writes to its ``status`` output each step.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["OTHER_STATUS", "SOFTEN_AFTER", "SOLVER_SUCCEEDED", "SolveStatus", "status_code"]

#: The solvers' success status (casadi ``sqpmethod``, IPOPT and the kernel's SQP alike).
SOLVER_SUCCEEDED = "Solve_Succeeded"


class SolveStatus(StrEnum):
    """How a solve ended (the value is what ``FHOCPResult.status`` holds and the results
    show)."""

    #: the solver succeeded and the answer passed the independent check
    OPTIMAL = "optimal"
    #: the ``i = 0`` output constraint fails at ``x̂``: no solve (the problem is infeasible)
    INFEASIBLE_X0 = "infeasible_x0"
    #: IPOPT proved the problem locally infeasible
    INFEASIBLE = "Infeasible_Problem_Detected"
    #: the iteration cap (SQP, IPOPT)
    MAXIMUM_ITERATIONS_EXCEEDED = "Maximum_Iterations_Exceeded"
    #: the optional wall-time budget (``time_budget``) ran out
    TIME_BUDGET_EXCEEDED = "time_budget_exceeded"
    #: the solver reported success but the answer failed the independent check
    RESIDUAL_CHECK_FAILED = "residual_check_failed"
    #: casadi ``sqpmethod`` stopped (a failed QP) and left the previous solve's status
    SOLVER_ABORTED = "solver_aborted"
    #: casadi 3.8 ``sqpmethod`` has no statistics after a failed line search
    STATS_UNAVAILABLE = "Solver_Stats_Unavailable"
    #: not a solve: an input sequence evaluated as given (the fallback candidate)
    CANDIDATE = "candidate"


#: The hard phase's statuses after which a softened FHOCP solves its softened problem
#: (:mod:`controllers.ocp.soft`): the problem had no answer (IPOPT's proof, the SQP's QP
#: infeasible), or its QP failed (the kernel's, or casadi ``sqpmethod``'s qpOASES).
SOFTEN_AFTER = frozenset({SolveStatus.INFEASIBLE, "QP_Infeasible", "QP_Failed",
                          SolveStatus.SOLVER_ABORTED, SolveStatus.STATS_UNAVAILABLE})

#: Codes of :func:`status_code` (the ``status`` output of the controller each step).
_CODES = {SolveStatus.OPTIMAL: 0, SolveStatus.INFEASIBLE_X0: 1, SolveStatus.INFEASIBLE: 2,
          SolveStatus.MAXIMUM_ITERATIONS_EXCEEDED: 3, "Maximum_WallTime_Exceeded": 3,
          "Maximum_CpuTime_Exceeded": 3, SolveStatus.TIME_BUDGET_EXCEEDED: 3,
          SolveStatus.RESIDUAL_CHECK_FAILED: 4}
#: The code of every other status.
OTHER_STATUS = 5


def status_code(status: str) -> int:
    """The step's status as a number: 0 optimal, 1 infeasible at ``x̂``, 2 infeasible, 3 an
    iteration or time limit, 4 the answer check failed, 5 anything else."""
    return _CODES.get(status, OTHER_STATUS)
