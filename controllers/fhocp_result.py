"""One solve of ``eq:optimization`` (:class:`FHOCPResult`) and its residuals from the compiled
answer check (:func:`set_residuals`): what :mod:`controllers.fhocp` returns and what the
kernel's self-test (:mod:`controllers.nlp_single_shooting`) compares, in a module of its own
so that neither imports the other."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["FHOCPResult", "set_residuals"]


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
        ``"optimal"``, ``"infeasible_x0"`` (the ``i = 0`` constraint fails at ``x̂``), or the
        solver's return status when it failed.
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
        a feasible, suboptimal sequence).
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
    lam_x: np.ndarray | None = field(default=None, repr=False)
    lam_g: np.ndarray | None = field(default=None, repr=False)
    #: the tracking FHOCP's artificial steady input and state (:mod:`controllers.fhocp_tracking`)
    u_s: np.ndarray | None = None
    x_s: np.ndarray | None = field(default=None, repr=False)


def set_residuals(res: FHOCPResult, out: np.ndarray, alpha: float) -> None:
    """:meth:`FHOCP._residuals` from the compiled check's ``out`` (:meth:`controllers.
    kernel_lib.Workspace.assess`)."""
    res.constraint_violation = max(0.0, float(out[1]), float(out[2]), float(out[3]) - 1.0)
    res.terminal_violation = max(0.0, float(out[4]) - alpha)
    res.active = int(out[5])
