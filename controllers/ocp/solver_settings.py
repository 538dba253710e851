"""Solver settings of the FHOCP, chosen by measurement (docs: design/solver.md).

The tolerances an answer must meet to be applied, the IPOPT options of the fast
formulation, and the options of the default solver, an SQP on the exact, eigenvalue-clipped
Hessian (:class:`controllers.ocp.fhocp.FHOCP`): inside the compiled kernel with its own dense
QP, or casadi ``sqpmethod`` with dense qpOASES QPs.
"""

from __future__ import annotations

from typing import Any

__all__ = ["DEFECT_TOL", "FAST_IPOPT_OPTIONS", "FEAS_TOL", "SQP_OPTIONS"]

#: Residual tolerances of an accepted answer (normalised units).
FEAS_TOL = 1e-7
DEFECT_TOL = 1e-8

#: IPOPT options of the fast formulation (chosen by measurement; docs: design/solver.md).
FAST_IPOPT_OPTIONS: dict[str, Any] = {
    "tol": 1e-6,
    "acceptable_tol": 1e-5,
    "constr_viol_tol": 1e-9,
    "mu_strategy": "adaptive",
    "fast_step_computation": "yes",   # no KKT residual check per linear solve: −0.4 ms
    "nlp_scaling_method": "none",
    "mumps_scaling": 0,
    "mumps_permuting_scaling": 0,
    "mumps_pivot_order": 0,
    "mu_init": 1e-4,
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_bound_frac": 1e-6,
    "warm_start_slack_bound_push": 1e-6,
    "warm_start_slack_bound_frac": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
    "max_iter": 15,
    "print_level": 0,
    "sb": "yes",
}

#: Options of the default solver (``solver="sqp"``), chosen by measurement (docs:
#: design/solver.md, design/compiled-kernel.md). ``loop`` (our key): ``"kernel"`` runs the whole
#: SQP inside the compiled kernel (:mod:`controllers.kernel.kernel_sqp`: casadi ``sqpmethod``'s
#: iteration with a dense dual active-set QP; 6–9× faster than qpOASES per QP, the gap growing
#: with N), ``"casadi"`` casadi ``sqpmethod`` with the QP below; without a kernel
#: (``kernel="numpy"``, no compiler) it is always casadi's. The exact Hessian from the same
#: callbacks, with its eigenvalues clipped at ``hessian_eigen_clip`` (numpy ``eigh`` in the
#: callback; our key, not passed to casadi) for the QP. Rejected: sqpmethod's ``regularize``
#: (Gershgorin shift) makes the iterates crawl; a 1e-7 clipping margin gives steps the ℓ1-merit
#: line search rejects; its ``eigen-clip`` needs many Jacobi sweeps (at the default 200 it aborts
#: without a status). Dense active-set QPs by ``qpOASES`` (``daqp`` stalled at zero steps near
#: regulation: 157 fallbacks on leak_tank1); ``tol_pr`` below the residual check's 1e-7; the same
#: 15-iteration cap as IPOPT.
SQP_OPTIONS: dict[str, Any] = {
    "loop": "kernel",
    "qpsol": "qpoases",
    "qpsol_options": {"printLevel": "none", "sparse": False, "error_on_fail": False},
    "hessian_eigen_clip": 1e-2,
    "tol_pr": 1e-8,
    "tol_du": 1e-6,
    "max_iter": 15,
    "print_header": False,
    "print_iteration": False,
    "print_status": False,
    "error_on_fail": False,
}
