"""The FHOCP's SQP run inside the compiled kernel (``controllers/kernel/sqp.c``).

casadi ``sqpmethod`` calls its QP through a conic plugin, and its only dense active-set
plugin, qpOASES, rebuilds the projected Hessian ``Zᵀ H Z`` at every call because H changes:
O((N m)³) per QP, 3 ms of a 5.7 ms step at N = 60 and 27 of 35 ms at N = 120 (docs:
design/compiled-kernel.md). The kernel therefore carries the whole SQP: the same iteration
as ``sqpmethod`` (exact eigenvalue-clipped Hessian, ℓ1-merit Armijo line search, the same
stopping tests and return statuses) with a dense Goldfarb–Idnani dual active-set QP
(``controllers/kernel/qp.c``) that factorises H once per QP and updates its factors per
working-set change; the stopping test's ∇L comes from one adjoint sweep, so the
sensitivities and the Jacobian are computed only when another iteration follows.

:class:`KernelSQP` stands where the casadi solver stood in :class:`controllers.ocp.fhocp.FHOCP`:
the same named argument and result arrays (``x0, p, lbx, ubx, lbg, ubg, lam_x0, lam_g0`` →
``x, f, g, lam_x, lam_g, lam_p``), a trigger, and ``stats()`` with casadi's keys
(``return_status``, ``success``, ``iter_count`` and the cumulative ``t_wall_*`` timers of
``sqpmethod``, plus ``derivative_reuses``, ``fresh_restarts`` and
``discarded_iterations``), so that the answer check and the warm start are
unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from controllers.errors import DesignError
from controllers.kernel.kernel_abi import SqpInfo, SqpOptions, SqpStatus

__all__ = ["STATUS", "KernelSQP"]

#: The kernel SQP's statuses by value, as casadi ``sqpmethod`` names them
#: (:class:`controllers.kernel.kernel_abi.SqpStatus`).
STATUS = tuple(status.casadi_name for status in SqpStatus)

#: casadi ``sqpmethod`` defaults of the line search and the step test (casadi 3.8).
LINE_SEARCH_DEFAULTS = {"min_step_size": 1e-10, "c1": 1e-4, "beta": 0.8, "max_iter_ls": 3}
#: ``sqpmethod`` options that do not change the iteration (its QP plugin, printing).
IGNORED = {"qpsol", "qpsol_options", "print_header", "print_iteration", "print_status",
           "print_time", "error_on_fail", "verbose"}


class KernelSQP:
    """The SQP of one FHOCP in one compiled call.

    Parameters
    ----------
    workspace : controllers.kernel.kernel_lib.Workspace
        The FHOCP's workspace of its problem's kernel (derivatives, eigenvalue clipping, QP
        and SQP loop).
    options : mapping
        ``tol_pr``, ``tol_du``, ``max_iter`` and optionally ``min_step_size``, ``c1``,
        ``beta``, ``max_iter_ls`` (casadi ``sqpmethod``'s meanings and defaults),
        ``tol_du_relative`` and ``reuse_step`` (ours, off by default:
        :class:`controllers.kernel.kernel_abi.SqpOptions`).
    time_budget : float, optional
        Wall-time budget of one solve [s] (status ``"User_Requested_Stop"`` when it runs out
        before convergence); none by default.

    Attributes
    ----------
    workspace : controllers.kernel.kernel_lib.Workspace
        The solver instance it runs in (its clipping counters: ``workspace.counters()``).
    info : controllers.kernel.kernel_abi.SqpInfo
        What the last solve reported (status, iterations, timers).
    """

    def __init__(self, workspace: Any, options: Mapping[str, Any],
                 time_budget: float | None = None) -> None:
        known = {"tol_pr", "tol_du", "tol_du_relative", "reuse_step", "max_iter",
                 *LINE_SEARCH_DEFAULTS, *IGNORED}
        unknown = sorted(set(options) - known)
        if unknown:
            raise DesignError(f"sqp_options {unknown[0]!r} is not supported by the kernel's "
                              "SQP (loop=\"kernel\"); use loop=\"casadi\" for sqpmethod's "
                              "other options")
        opts = {**LINE_SEARCH_DEFAULTS, **options}
        self.workspace = workspace
        nw, ng, npar = workspace.nw, workspace.ng, workspace.npar
        self.ins = {name: np.zeros(size) for name, size in (
            ("x0", nw), ("p", npar), ("lbx", nw), ("ubx", nw), ("lbg", ng), ("ubg", ng),
            ("lam_x0", nw), ("lam_g0", ng))}
        self.outs = {name: np.zeros(size) for name, size in (
            ("x", nw), ("f", 1), ("g", ng), ("lam_x", nw), ("lam_g", ng), ("lam_p", npar))}
        self.options = SqpOptions(
            tol_pr=float(opts["tol_pr"]), tol_du=float(opts["tol_du"]),
            max_iter=int(opts["max_iter"]), max_iter_ls=int(opts["max_iter_ls"]),
            min_step_size=float(opts["min_step_size"]), c1=float(opts["c1"]),
            beta=float(opts["beta"]),
            tol_du_relative=int(bool(opts.get("tol_du_relative", False))),
            reuse_step=float(opts.get("reuse_step", 0.0)),
            time_budget=np.inf if time_budget is None else float(time_budget))
        self.info = SqpInfo()
        self._timers = np.zeros(4)    # QP, Hessian, f/g/derivatives, line search [s]
        self._stats: dict[str, Any] | None = None
        i, o = self.ins, self.outs
        self._call = workspace.sqp_call({
            "p": i["p"], "lbx": i["lbx"], "ubx": i["ubx"], "lbg": i["lbg"], "ubg": i["ubg"],
            "w": o["x"], "lam_x": o["lam_x"], "lam_g": o["lam_g"], "g": o["g"], "f": o["f"]},
            self.options, self.info)

    def buffers(self) -> tuple[KernelSQP, Any, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """``(self, trigger, ins, outs)``, as
        :func:`controllers.ocp.casadi_callbacks.bind_buffers` gives for a casadi solver."""
        return self, self.solve, self.ins, self.outs

    def solve(self) -> None:
        """Run the SQP from ``ins`` (the initial guess and the problem's data) into
        ``outs``."""
        o, i = self.outs, self.ins
        o["x"][:] = i["x0"]
        o["lam_x"][:] = i["lam_x0"]
        o["lam_g"][:] = i["lam_g0"]
        status = self._call()
        info = self.info
        self._timers += (info.t_qp, info.t_hessian, info.t_derivatives, info.t_line_search)
        t = self._timers
        self._stats = {
            "return_status": status.casadi_name,
            "success": status == SqpStatus.SOLVE_SUCCEEDED,
            # every iteration of the solve: a discarded reuse loop's too (fresh_restarts)
            "iter_count": info.iterations + info.discarded_iterations,
            "qp_working_set_changes": info.qp_working_set_changes,
            "line_search_failures": info.line_search_failures,
            "derivative_reuses": info.derivative_reuses,
            "fresh_restarts": info.fresh_restarts,
            "discarded_iterations": info.discarded_iterations,
            "t_wall_QP": t[0], "t_wall_nlp_hess_l": t[1], "t_wall_nlp_jac_fg": t[2],
            "t_wall_nlp_fg": t[3]}

    def stats(self) -> dict[str, Any]:
        """The last solve's status and counts; the ``t_wall_*`` timers accumulate over the
        object's lifetime, as casadi's do."""
        if self._stats is None:
            raise RuntimeError("no stats available: the kernel SQP has not run")
        return dict(self._stats)
