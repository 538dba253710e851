"""The compiled kernel's interface types, defined once for C and Python.

The kernel's SQP (``controllers/kernel/sqp.c``) takes its options and returns its counts and
timers as named C structs, its answer check returns an :class:`Assessment`, and reports its
outcome, and its QP's, as named enums. Each is declared here once, as a :mod:`ctypes` structure
or an :class:`~enum.IntEnum`, and :func:`c_declarations` writes the matching C
``typedef``/``enum`` into every generated kernel source
(:func:`controllers.kernel.compiled_kernel.generate_source`), so that the two sides cannot
disagree on a field's position or a status's value (acados shares its option and status names
between C and Python in the same spirit). :func:`check_layout` compares the sizes the compiler
chose with ctypes' when a library is loaded.
"""

from __future__ import annotations

import ctypes
from enum import IntEnum
from typing import Any

__all__ = ["ABI_COUNT", "Assessment", "Counters", "Dims", "QpStatus", "SqpInfo", "SqpOptions",
           "SqpStatus", "c_declarations", "check_layout"]


class SqpOptions(ctypes.Structure):
    """The SQP's options (C ``gk_sqp_opts``): casadi ``sqpmethod``'s meanings.

    Attributes
    ----------
    tol_pr, tol_du : float
        Primal infeasibility and dual (∇L ∞-norm) tolerances of the stopping test.
    max_iter : int
        Iteration limit.
    max_iter_ls : int
        Line-search trials per iteration (0: full steps).
    min_step_size : float
        The step ‖Δw‖∞ at or below which the iteration stops (after the first).
    c1, beta : float
        Armijo constant and backtracking factor of the ℓ1-merit line search.
    time_budget : float
        Wall-time budget of one solve [s] (``inf``: none).
    tol_du_relative : int
        1: the dual test is ``‖∇L‖∞ < tol_du (1 + ‖(λ_g, λ_x)‖∞)``, relative to the
        multipliers' size (ours: rounding in ``∇L`` keeps an absolute 10⁻⁶ out of reach when
        the multipliers reach 10⁵); 0: ``sqpmethod``'s absolute test.
    reuse_step : float
        Ours (0: off, ``sqpmethod``'s iteration): an iteration keeps the last Jacobian and
        Hessian, with the adjoint-corrected gradient ``∇L − J_dᵀλ_g − λ_x`` for the QP, while
        the iterates have moved at most this far (∞-norm, summed over the steps) since they
        were evaluated (``controllers/kernel/sqp.c``, ``iterate``).
    """

    _fields_ = [("tol_pr", ctypes.c_double), ("tol_du", ctypes.c_double),
                ("max_iter", ctypes.c_int), ("max_iter_ls", ctypes.c_int),
                ("min_step_size", ctypes.c_double), ("c1", ctypes.c_double),
                ("beta", ctypes.c_double), ("time_budget", ctypes.c_double),
                ("tol_du_relative", ctypes.c_int), ("reuse_step", ctypes.c_double)]


class SqpInfo(ctypes.Structure):
    """What one SQP solve reports (C ``gk_sqp_info``).

    Attributes
    ----------
    status : int
        A :class:`SqpStatus`.
    iterations, qp_working_set_changes, line_search_failures : int
    t_qp, t_hessian, t_derivatives, t_line_search : float
        Seconds in the QPs, the Hessians (eigenvalue clipping included), f/∇f/g/∂g (the
        stopping tests' and the iterations') and the line searches' f/g.
    t_clip : float
        Of ``t_hessian``, the seconds in the eigenvalue clipping.
    derivative_reuses : int
        Iterations that kept the Jacobian and the Hessian (``reuse_step``), a discarded
        loop's included.
    fresh_restarts : int
        1 when a loop that reused derivatives ended short of success and the solve started
        again from its initial guess with fresh derivatives (so that reuse never costs
        convergence: the answer is then the fresh-derivative solve's), else 0.
    discarded_iterations : int
        The iterations of that discarded loop (``iterations`` counts the answer's loop).
    """

    _fields_ = [("status", ctypes.c_int), ("iterations", ctypes.c_int),
                ("qp_working_set_changes", ctypes.c_int),
                ("line_search_failures", ctypes.c_int),
                ("t_qp", ctypes.c_double), ("t_hessian", ctypes.c_double),
                ("t_derivatives", ctypes.c_double), ("t_line_search", ctypes.c_double),
                ("derivative_reuses", ctypes.c_int), ("fresh_restarts", ctypes.c_int),
                ("discarded_iterations", ctypes.c_int), ("t_clip", ctypes.c_double)]


class SqpStatus(IntEnum):
    """How an SQP solve ended (C ``enum gk_sqp_status``, ``GK_SQP_<NAME>``); casadi
    ``sqpmethod``'s return statuses (:attr:`casadi_name`)."""

    SOLVE_SUCCEEDED = 0
    MAXIMUM_ITERATIONS_EXCEEDED = 1
    SEARCH_DIRECTION_BECOMES_TOO_SMALL = 2
    QP_INFEASIBLE = 3
    #: the QP hit its working-set change limit or H was not positive definite
    QP_FAILED = 4
    #: the time budget ran out (:class:`controllers.ocp.fhocp.FHOCP` reports
    #: ``"time_budget_exceeded"``, as for casadi's loop)
    USER_REQUESTED_STOP = 5

    @property
    def casadi_name(self) -> str:
        """The name casadi ``sqpmethod`` gives this outcome (``"Solve_Succeeded"``, …)."""
        return _CASADI_NAMES[self]


_CASADI_NAMES = {
    SqpStatus.SOLVE_SUCCEEDED: "Solve_Succeeded",
    SqpStatus.MAXIMUM_ITERATIONS_EXCEEDED: "Maximum_Iterations_Exceeded",
    SqpStatus.SEARCH_DIRECTION_BECOMES_TOO_SMALL: "Search_Direction_Becomes_Too_Small",
    SqpStatus.QP_INFEASIBLE: "QP_Infeasible",
    SqpStatus.QP_FAILED: "QP_Failed",
    SqpStatus.USER_REQUESTED_STOP: "User_Requested_Stop",
}


class Assessment(ctypes.Structure):
    """The independent check of one input sequence (C ``gk_assessment``; the kernel's
    ``assess`` and ``assess_w``, :class:`controllers.kernel.kernel_lib.Workspace`): what
    :func:`controllers.ocp.fhocp_result.set_residuals` and the answer check read.

    Attributes
    ----------
    cost : float
        The cost ``eq:optimization-cost`` with ``t = ‖x_N − x_ref‖∞`` (the tracking FHOCP's
        with its offset and last input-rate terms, for ``assess_w`` of a tracking kernel).
    violation_first, violation_rows : float
        ``max_j (L U_o x_i − bnd_i)_j`` over the ``i = 0`` rows, and over ``i ≥ 1`` (``−inf``
        when there are none).
    u_max : float
        ``max |u|``.
    terminal_distance : float
        ``‖x_N − x_ref‖∞``.
    active : int
        Active constraints: output rows ``i ≥ 1`` and the terminal set within 10⁻⁶, inputs
        with ``|u| > 1 − 10⁻⁶``.
    defect : float
        ``assess_w``: ``max |x_solver − x|`` against the solver's own trajectory.
    steady_residual : float
        ``assess_w`` of a tracking kernel: ``‖f(x_s, u_s) − x_s‖∞`` of its steady state by a
        plain GRU step (NaN when Newton failed); 0 otherwise.
    """

    _fields_ = [("cost", ctypes.c_double), ("violation_first", ctypes.c_double),
                ("violation_rows", ctypes.c_double), ("u_max", ctypes.c_double),
                ("terminal_distance", ctypes.c_double), ("active", ctypes.c_int),
                ("defect", ctypes.c_double), ("steady_residual", ctypes.c_double)]


class Dims(ctypes.Structure):
    """A kernel library's dimensions (C ``gk_dims``, ``PFX(dims)``).

    Attributes
    ----------
    n_states, n_inputs, horizon : int
        n, m and N of the FHOCP.
    n_outputs : int
        p, the model's outputs.
    n_reduced_rows : int
        The reduced output-constraint rows ``D U_o`` of the NLP's constraints (q).
    n_decision, n_constraints, n_parameters : int
        The NLP's sizes: ``w``, ``g(w, p)`` and ``p``.
    control_horizon : int
        M ≤ N: the free inputs (the tail held at ``u_s`` below N).
    n_assess_rows : int
        The full output-constraint rows ``L U_o`` of the answer check.
    """

    _fields_ = [(name, ctypes.c_long) for name in (
        "n_states", "n_inputs", "horizon", "n_reduced_rows", "n_decision", "n_constraints",
        "n_parameters", "control_horizon", "n_assess_rows", "n_outputs")]


class Counters(ctypes.Structure):
    """A solver instance's eigenvalue-clipping counts (C ``gk_counters``, ``PFX(counters)``):
    Hessians clipped (``hess_calls``), eigen-decompositions (``eig``), decompositions that
    clipped (``clipped``), eigenvalues clipped (``eigenvalues_clipped``) and decompositions
    that fell back from the eigenpairs below the margin to the full one (``full_eig``)."""

    _fields_ = [(name, ctypes.c_long) for name in (
        "hess_calls", "eig", "clipped", "eigenvalues_clipped", "full_eig")]


class QpStatus(IntEnum):
    """How the kernel's QP ended (C ``enum gk_qp_status``, ``GK_QP_<NAME>``)."""

    OPTIMAL = 0
    INFEASIBLE = 1
    #: the working-set change limit, 10 (nw + ng), was reached
    CHANGE_LIMIT = 2
    NOT_POSITIVE_DEFINITE = 3


_C_TYPES = {ctypes.c_double: "double", ctypes.c_int: "int", ctypes.c_long: "long"}
_STRUCTS: tuple[tuple[str, Any], ...] = (("gk_sqp_opts", SqpOptions), ("gk_sqp_info", SqpInfo),
                                         ("gk_assessment", Assessment), ("gk_dims", Dims),
                                         ("gk_counters", Counters))
#: Entries of ``PFX(abi)``: the size of each struct above, then of the solver instance.
ABI_COUNT = len(_STRUCTS) + 1
_ENUMS: tuple[tuple[str, str, Any], ...] = (("gk_sqp_status", "GK_SQP_", SqpStatus),
                                            ("gk_qp_status", "GK_QP_", QpStatus))


def c_declarations() -> str:
    """The C declarations of every type above (part of each generated kernel source)."""
    out = ["/* interface types, generated from controllers/kernel/kernel_abi.py */\n"]
    for cname, struct in _STRUCTS:
        fields = " ".join(f"{_C_TYPES[t]} {name};" for name, t in struct._fields_)
        out.append(f"typedef struct {cname} {{ {fields} }} {cname};\n")
    for cname, prefix, enum in _ENUMS:
        members = ", ".join(f"{prefix}{m.name} = {int(m)}" for m in enum)
        out.append(f"enum {cname} {{ {members} }};\n")
    sizes = ", ".join(f"(long)sizeof({cname})" for cname, _ in _STRUCTS)
    out.append(f"#define GK_ABI_COUNT {ABI_COUNT}\n"
               f"#define GK_ABI_SIZES {{{sizes}, (long)sizeof(gk_ws)}}\n")
    return "".join(out)


def check_layout(sizes: tuple[int, ...]) -> None:
    """Raise :class:`OSError` when the library's ``sizeof`` of each struct above
    (``gk_sqp_opts``, ``gk_sqp_info``, ``gk_assessment``, ``gk_dims``, ``gk_counters``: the
    first entries of ``PFX(abi)``) differs from ctypes' (a compiler with another ABI)."""
    ours = tuple(ctypes.sizeof(struct) for _, struct in _STRUCTS)
    if tuple(sizes[:len(ours)]) != ours:
        raise OSError(f"interface struct sizes {tuple(sizes)} differ from ctypes' {ours}")
