"""The FHOCP of the robust MPC, ``eq:optimization`` (Definition 5): declare, set up, solve.

    min_u  Σ_{i=0}^{N-1} ‖x_i − x̄‖²_Q + ‖u_i − ū‖²_R  +  s ‖x_N − x̄‖²_∞
           [ + Σ_{i=0}^{N-1} ‖u_i − u_{i−1}‖²_S,  S = diag(du_weight) ]
    s.t.   x_0 = x̂_k,  x_{i+1} = f(x_i, u_i)                          (eq:gru)
           L(U_o x_i + b_o) + w_L ≤ h − a_i ê_o,k − b_i,  i = 0 … N−1  (eq:optimization-constraint)
           ‖u_i‖∞ ≤ 1                                                   (eq:input-constraint)
           ‖x_N − x̄‖∞ ≤ α                                               (eq:terminal_constraint)

(the paper's ``x_N + x̄`` in the terminal cost is a typo: it is ``x_N − x̄``). The ∞-norm term is
written with an epigraph variable ``t``: ``−t ≤ x_N − x̄ ≤ t`` element-wise, cost ``s t²``,
``0 ≤ t ≤ α`` (so the terminal set is a bound on ``t``). Everything that depends on the
set-point or on time (x̂, x̄, ū, α, ê_o and the tightened bounds) is a parameter or a bound, so
the problem is built once (:meth:`FHOCP.setup`) and solved every step (:meth:`FHOCP.solve`).
The bracketed input-rate term is outside the paper's cost and off by default (``du_weight``
all zero: the term, and the parameter ``u_{−1}`` it needs, do not exist);
``u_{−1}`` is the input applied at the previous step, a parameter of the solve
(:mod:`controllers.ocp.input_rate`).

Two formulations of the same problem: ``"single-shooting"`` (default, fast: the inputs and
``t`` are the variables, exact derivatives from numpy callbacks; :mod:`controllers.
nlp_single_shooting`), solved by an SQP (:data:`~controllers.ocp.solver_settings.SQP_OPTIONS`,
at most 15 iterations, no wall-clock limit: deterministic) -- inside the compiled kernel
with its own dense QP (:mod:`controllers.kernel.kernel_sqp`), else casadi ``sqpmethod`` with dense
qpOASES QPs -- or by IPOPT (``solver="ipopt"``), warm started with the primal and
dual solution shifted by one stage; and ``"multiple-shooting"`` (the plain baseline, what
do-mpc builds; :mod:`controllers.ocp.nlp_multiple_shooting`). The ``i = 0`` constraint involves
only ``x̂``: it is checked before the solve (:meth:`FHOCP.x0_infeasible`), and a violated one
is reported as ``"infeasible_x0"`` without calling the solver. The design record (docs:
design/solver.md) lists the alternatives measured and why they won or lost.

One class for every control law, with a pluggable reference: what differs between the laws
(the reference and its artificial steady state, the terminal ingredients, the layout of ``w``,
the answer check) is a strategy object (:class:`controllers.ocp.reference.Reference`): the
paper's set-point (:class:`~controllers.laws.paper.reference.FixedSetpoint`) or the
tracking law's artificial steady state
(:class:`~controllers.laws.tracking.reference.ArtificialSteadyState`). One solve procedure
serves them all (:meth:`FHOCP.solve`): the ``i = 0`` row, the solver within its budget, the
reference's independent answer check, the judge and the warm start.

Every answer is checked independently of the solver's status: the inputs are rolled out with
numpy (:func:`controllers.gru.simulate`) and the constraint violations, the terminal-set
violation and the defect between the solver's and numpy's trajectories are measured (see
:class:`FHOCPResult`). An answer is accepted only when the solver reports success AND these
residuals are within tolerance: :func:`controllers.ocp.fhocp_result.judge`, the one judge of
every law, whose statuses are :class:`controllers.ocp.solve_status.SolveStatus` (the kernel's
too).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from controllers import gru
from controllers.dead_time import InputPrefix
from controllers.errors import DesignError
from controllers.kernel.compiled_kernel import KERNEL_SELF_TEST_TOL, for_fhocp
from controllers.ocp.casadi_callbacks import bind_buffers, quiet_stdout
from controllers.ocp.fhocp_result import FHOCPResult
from controllers.ocp.fhocp_solve import Solving
from controllers.ocp.input_rate import du_weights
from controllers.ocp.reference import Reference
from controllers.ocp.soft import Slacks
from controllers.ocp.solver_settings import FAST_IPOPT_OPTIONS, SQP_OPTIONS

__all__ = ["FHOCP", "KERNEL_SELF_TEST_TOL", "FHOCPData", "FHOCPResult", "bind_buffers"]



@dataclass(frozen=True)
class FHOCPData:
    """What ``eq:optimization`` is made of: the model, the weights, the constraints and their
    tightening (the quantities of a :class:`~controllers.certification.certificates.Certificate`
    of that name, for a problem built without one).

    Attributes
    ----------
    params : mapping of arrays
        GRU weights (``eq:gru``).
    N : int
        Prediction horizon.
    Q, R : arrays
        Positive definite weights (n×n, m×m).
    L, h : arrays
        Output polytope ``L y ≤ h`` (``eq:output-constraint``), normalised units.
    w_L : (q,) array
        Output-noise tightening ``w_L(j) = Σ_k |L_jk| w̄_y``.
    a, b : (N + 1, q) arrays
        Tightening coefficients ``eq:constraint_tightening_parameters``.
    s : float
        Terminal weight ``eq:definition_s``.
    """

    params: Mapping[str, np.ndarray]
    N: int
    Q: np.ndarray
    R: np.ndarray
    L: np.ndarray
    h: np.ndarray
    w_L: np.ndarray
    a: np.ndarray
    b: np.ndarray
    s: float


class FHOCP(Solving):
    """The FHOCP ``eq:optimization`` of a control law: declare, :meth:`setup` once,
    :meth:`solve` each step.

    Parameters
    ----------
    data : FHOCPData or Certificate
        What the problem is made of (:class:`FHOCPData`'s attributes; a
        :class:`~controllers.certification.certificates.Certificate` has them all).
    reference : Reference
        The control law's part of the problem (:class:`controllers.ocp.reference.Reference`):
        the paper's set-point, :class:`~controllers.laws.paper.reference.FixedSetpoint`, or
        the tracking law's :class:`~controllers.laws.tracking.reference.
        ArtificialSteadyState`. The object then serves this problem (as ``reference``).
    formulation : {"single-shooting", "multiple-shooting"}
        Multiple shooting is the plain baseline of the paper's law.
    ipopt_options : dict, optional
        Overrides of the IPOPT options (``FAST_IPOPT_OPTIONS`` for single shooting, IPOPT
        defaults for multiple shooting).
    solver : {"sqp", "ipopt"}, optional
        Solver of the single-shooting formulation (default ``"sqp"``; ``"ipopt"`` when
        ``ipopt_options`` are given, and always for multiple shooting).
    sqp_options : dict, optional
        Overrides of :data:`~controllers.ocp.solver_settings.SQP_OPTIONS` and of the reference's
        (``loop``: ``"kernel"``, the SQP in the compiled kernel, or ``"casadi"``,
        ``sqpmethod``; ``tol_du_relative``: the kernel's relative dual test, ignored by
        ``sqpmethod``).
    time_budget : float, optional
        Wall-time budget of one solve [s] (status ``"time_budget_exceeded"``). Off by
        default: a wall-clock limit makes closed-loop results depend on the machine.
    kernel : {"auto", "numpy"}
        Derivatives of the single-shooting SQP: ``"auto"`` the compiled kernel
        (:mod:`controllers.kernel.compiled_kernel`) when it can be built, ``"numpy"`` the numpy
        callbacks (the reference implementation, and the fallback).
    du_weight : float or (m,) array
        Diagonal of the input-rate weight ``S`` (normalised units; one number: every input).
        0 (default): no input-rate term, the paper's cost.
    max_move : (m,) array, optional
        ``Δ``, the largest move of each input per stage (normalised): the rows
        ``eq:move-constraint`` (:class:`controllers.ocp.input_rate.MoveRows`) of the
        single-shooting FHOCP; ``None`` (default): none.

    Attributes
    ----------
    reference : Reference
        The control law's part (above).
    has_du : bool
        The cost has the input-rate term (some ``du_weight`` > 0); then ``p`` ends with
        ``u_{−1}``.
    nw, ng, npar, it, iu, ix
        The reference's layout of ``w``, ``g`` and ``p``
        (:class:`controllers.ocp.reference.Reference`).
    warm_start : dict or None
        The previous accepted solve's ``w``, ``lam_x``, ``lam_g`` (the next one's warm start).
    move : MoveRows or None
        The move limit's rows (the last ``nmv`` rows of ``g``), ``None`` without one.
    operator : OperatorTerms or None
        What the operator's settings impose on the next solve
        (:class:`controllers.ocp.operator_terms.OperatorTerms`), ``None``: nothing.
    """

    def __init__(self, data: FHOCPData | Any, *, reference: Reference,
                 formulation: str = "single-shooting",
                 ipopt_options: Mapping[str, Any] | None = None,
                 time_budget: float | None = None,
                 solver: str | None = None,
                 sqp_options: Mapping[str, Any] | None = None, kernel: str = "auto",
                 du_weight: float | np.ndarray = 0.0, soft: bool = False,
                 soft_weight: float | None = None,
                 max_move: np.ndarray | None = None) -> None:
        self.reference: Any = reference
        if max_move is not None and formulation != "single-shooting":
            raise DesignError("max_move is the single-shooting FHOCP's: the "
                              "multiple-shooting baseline has no move rows")
        self.max_move = None if max_move is None else np.asarray(max_move, dtype=float)
        self.move: Any = None
        self.nmv = 0
        self.operator: Any = None
        self._choose_solver(formulation, solver, ipopt_options, sqp_options, kernel, soft)
        #: the output rows and the terminal set are softened (:mod:`controllers.ocp.soft`)
        self.soft = bool(soft)
        self._soft_weight = soft_weight
        self.time_budget = None if time_budget is None else float(time_budget)
        self._declare(data, du_weight)
        self.reference.attach(self, data)   # its layout of w, g and p
        lay = self.reference
        self.nw, self.iu, self.it, self.ix = lay.nw, lay.iu, lay.it, lay.ix
        #: the slacks ``ε`` of the softened rows: their indices in ``w`` (after ``t``) and
        #: their weight ``ρ`` (:class:`controllers.ocp.soft.Slacks`), ``None`` when hard
        self.soft_design = (Slacks.of(self, self._soft_weight, self.it + 1) if self.soft
                            else None)
        #: the slacks as the solve in progress has them: the design's, or without weights
        #: in the hard phase (:meth:`solve_request`)
        self.slacks = self.soft_design
        self._soft_off = None if self.soft_design is None else self.soft_design.off()
        #: the solve in progress is the softened phase (:meth:`solve_request`)
        self.softening = False
        #: solve the softened phase alone, every step (the exact penalty's own answers: the
        #: design record's comparison and its test; off: the hard phase first)
        self.always_soften = False
        self.ng, self.npar = lay.ng, lay.npar
        self._solver = None
        self._nlp: Any = None
        self._buffer: tuple | None = None
        self.warm_start: dict[str, np.ndarray] | None = None
        #: the inputs already applied at the horizon's start (inputs whose dead time exceeds
        #: the shortest; :meth:`use_prefix`): none by default
        self.prefix = InputPrefix([0] * self.m)

    def _choose_solver(self, formulation: str, solver: str | None,
                       ipopt_options: Mapping[str, Any] | None,
                       sqp_options: Mapping[str, Any] | None, kernel: str, soft: bool) -> None:
        """The formulation, the solver and their options, checked (the constructor's
        arguments of those names)."""
        if formulation not in ("single-shooting", "multiple-shooting"):
            raise DesignError(f"unknown formulation {formulation!r}")
        if formulation not in self.reference.formulations:
            raise DesignError(f"the {self.reference.name} law's FHOCP is "
                              f"{' or '.join(self.reference.formulations)} only, not {formulation}")
        if soft and formulation != "single-shooting":
            raise DesignError("soft output constraints are the single-shooting FHOCP's: the "
                              "multiple-shooting baseline keeps them hard")
        if kernel not in ("auto", "numpy"):
            raise DesignError(f"kernel must be \"auto\" or \"numpy\", got {kernel!r}")
        self.kernel_mode = kernel
        self.kernel: Any = None
        self.kernel_error: str | None = None
        if solver is None:
            solver = "sqp" if formulation == "single-shooting" and not ipopt_options else "ipopt"
        if solver not in ("ipopt", "sqp") or (solver == "sqp"
                                               and formulation != "single-shooting"):
            raise DesignError(f"unknown solver {solver!r} for formulation {formulation!r}")
        self.solver = solver
        self.sqp_options = {**SQP_OPTIONS, **self.reference.sqp_overrides, **(sqp_options or {})}
        if self.sqp_options["loop"] not in ("kernel", "casadi"):
            raise DesignError(f"sqp_options loop must be \"kernel\" or \"casadi\", got "
                              f"{self.sqp_options['loop']!r}")
        self.formulation = formulation
        #: warm start the multipliers too (single shooting; not the plain baseline)
        self.warm_duals = formulation == "single-shooting"
        base = dict(FAST_IPOPT_OPTIONS) if formulation == "single-shooting" else {
            "print_level": 0, "sb": "yes"}
        base.update(ipopt_options or {})
        self.ipopt_options = base

    def use_prefix(self, prefix: InputPrefix) -> None:
        """Fix the FHOCP's first inputs of each input whose dead time exceeds the shortest
        (:class:`controllers.dead_time.InputPrefix`, its values set each step by the
        controller); the laws apply stage ``e_j`` of input ``j``.

        Raises
        ------
        DesignError
            A lag leaves no free stage of that input (it reaches the control horizon).
        """
        free = int(getattr(self.reference, "control_horizon", self.N))
        if prefix.lags.size != self.m:
            raise DesignError(f"{prefix.lags.size} input lags for {self.m} inputs")
        if prefix.depth >= free:
            raise DesignError(f"an input's dead time exceeds the shortest by {prefix.depth} "
                              f"samples: the FHOCP needs more than that many free stages "
                              f"(it has {free}; a longer horizon)")
        self.prefix = prefix

    # -- construction ------------------------------------------------------------------
    def _declare(self, data: Any, du_weight: float | np.ndarray) -> None:
        """The model, weights, constraint rows and tightening of ``data``."""
        self.params = {k: np.asarray(v, dtype=float) for k, v in data.params.items()}
        #: the model holds measured disturbances in its biases, moved each step
        #: (:meth:`shift_biases`; the compiled kernel's ``HAS_SHIFT``)
        self.bias_shift = getattr(getattr(data, "model", None), "held_from", None) is not None
        self.n, self.m, self.p = gru.dimensions(self.params)
        self.N = int(data.N)
        self.Q = np.asarray(data.Q, dtype=float)
        self.R = np.asarray(data.R, dtype=float)
        self.L = np.atleast_2d(np.asarray(data.L, dtype=float))
        self.q = self.L.shape[0]
        self.h = np.asarray(data.h, dtype=float).reshape(self.q)
        self.w_L = np.asarray(data.w_L, dtype=float).reshape(self.q)
        self.a = np.asarray(data.a, dtype=float)
        self.b = np.asarray(data.b, dtype=float)
        if self.a.shape[0] < self.N or self.b.shape[0] < self.N:
            raise DesignError(f"a and b need at least N = {self.N} rows (i = 0 … N−1)")
        self.a = self.a[: self.N].reshape(self.N, self.q)
        self.b = self.b[: self.N].reshape(self.N, self.q)
        self.s = float(data.s)
        #: how many slacks the softened rows add to ``w`` (:mod:`controllers.ocp.soft`)
        self.nsl = self.q + 1 if self.soft else 0
        self.du_weight = du_weights(du_weight, self.m)
        self.has_du = bool(np.any(self.du_weight > 0))
        self.LUo = self.L @ self.params["U_o"]
        self.Lbo = self.L @ self.params["b_o"]
        #: ``L d`` of :meth:`set_output_shift` (``None``: the rows as declared)
        self.output_shift: np.ndarray | None = None
        #: ``δ`` of the operator's limits (:attr:`operator`) the bounds were computed with
        self._narrowing: np.ndarray | None = None
        self._bounds_eo = float("nan")
        self._bounds = np.zeros((self.N, self.q))
        self._pair_rows()

    def _pair_rows(self) -> None:
        """Merge opposite rows of ``L`` (``L_k = −L_j``, a box) into two-sided constraints.

        The single-shooting NLP then has one row ``D U_o x_i`` with bounds
        ``[−rhs_k, rhs_j]`` per pair instead of two: a smaller KKT system. ``pair_up[r]`` /
        ``pair_lo[r]`` are the ``L`` rows giving the upper / lower bound of reduced row ``r``
        (−1: none). Softened rows are not paired: each row has its own slack.
        """
        if self.soft:
            self.qr, self.DUo = self.q, self.LUo
            self.pair_up, self.pair_lo = np.arange(self.q), np.full(self.q, -1)
            return
        used: set[int] = set()
        rows, up, lo = [], [], []
        for j in range(self.q):
            if j in used:
                continue
            used.add(j)
            k = next((k for k in range(j + 1, self.q) if k not in used
                      and np.allclose(self.L[k], -self.L[j], rtol=0, atol=1e-15)), -1)
            if k >= 0:
                used.add(k)
            rows.append(j)
            up.append(j)
            lo.append(k)
        self.qr = len(rows)
        self.DUo = self.LUo[rows]
        self.pair_up = np.array(up)
        self.pair_lo = np.array(lo)

    @classmethod
    def from_certificate(cls, cert: Any, **options: Any) -> FHOCP:
        """The FHOCP of a :class:`~controllers.certification.certificates.Certificate` (its
        weights, constraints, tightening and terminal weight); ``options`` as the
        constructor's keyword arguments (``reference``, ``formulation``, ``solver``, ...)."""
        return cls(cert, **options)

    def move_rows(self, free: np.ndarray, end_w: np.ndarray | None,
                  end_p: np.ndarray | None, nw: int) -> int:
        """The move limit's rows of a layout (:class:`~controllers.ocp.input_rate.MoveRows`
        along ``free`` ended by ``end_w`` or ``end_p``; a reference's :meth:`attach` calls
        it): how many rows they add to ``g`` (0 without ``max_move``)."""
        from controllers.ocp.input_rate import MoveRows

        if self.max_move is None:
            return 0
        self.move = MoveRows(np.broadcast_to(self.max_move, (self.m,)), free, end_w, end_p, nw)
        self.nmv = self.move.count
        return self.nmv

    def set_operator(self, terms: Any) -> None:
        """What the operator's settings impose on the next solves
        (:class:`controllers.ocp.operator_terms.OperatorTerms`; ``None``: nothing); a new
        narrowing of the output rows recomputes the tightened bounds."""
        self.operator = terms
        narrowing = None if terms is None or not np.any(terms.narrowing) else terms.narrowing
        if not _same(narrowing, self._narrowing):
            self._narrowing = None if narrowing is None else np.array(narrowing, dtype=float)
            self._bounds_eo = float("nan")

    @property
    def narrowing(self) -> np.ndarray | None:
        """``δ`` of the operator's limits in force (``eq:operator-rows``), ``None``: none."""
        return self._narrowing

    def setup(self) -> FHOCP:
        """Build the solver (a few ms; again after :meth:`setup` to restart it exactly).

        The single-shooting SQP takes its derivatives from the compiled kernel
        (:mod:`controllers.kernel.compiled_kernel`, the reference's variant) unless
        ``kernel="numpy"``, or when it cannot be built or fails its self-test (then the
        numpy callbacks of the reference's NLP, with a one-line warning). Returns ``self``.
        """
        self.kernel = None
        if self.formulation == "single-shooting":
            if self.solver == "sqp" and self.kernel_mode == "auto":
                self.kernel, self.kernel_error = for_fhocp(self)
            self._nlp = self.reference.nlp(self.kernel)
            self._shoot = self._nlp.shoot
            nlp, opts = self._nlp.ipopt_problem(self.ipopt_options, self.time_budget)
            self._xtraj = self._nlp.trajectory
        else:
            from controllers.ocp.nlp_multiple_shooting import multiple_shooting_problem

            self._nlp = None
            nlp, opts, xtraj, _ = multiple_shooting_problem(self)
            self._xtraj = lambda w, p: np.asarray(xtraj(w, p))
        self._build_solver(nlp, opts, "fhocp")
        return self

    def set_weight(self, weight: str, index: int, value: float) -> None:
        """Change one cost weight between solves (as acados' ``cost_set``): ``"R"`` (the
        diagonal entry ``index``), ``"du"`` (the input-rate weight of input ``index``; the
        term must exist) or ``"T"`` (the tracking law's offset weight of output ``index``),
        in the numpy problem and the compiled kernel's instance alike; the caller checks
        the value (:meth:`controllers.mpc.RobustMPC.set`)."""
        if weight == "R":
            self.R[index, index] = value
        elif weight == "du" and self.has_du:
            self.du_weight[index] = value
        elif weight == "T" and getattr(self.reference, "offset_weight", None) is not None:
            self.reference.offset_weight[index] = value
        else:
            raise DesignError(f"the FHOCP has no weight {weight!r} to set")
        if self._nlp is not None:
            self._nlp.weights_changed()
        if self.kernel is not None:
            self.kernel.set_weights(self.R, self.du_weight if self.has_du else None,
                                    getattr(self.reference, "offset_weight", None))

    def shift_biases(self, db: np.ndarray, changed: bool) -> None:
        """The measured disturbances held over the horizon moved the model's biases in place
        (:class:`controllers.disturbances.BiasShift`, shift ``db`` from the nominal ones):
        forget what was computed at the old ones (``changed``) and give the compiled kernel
        the shift (its numbers stay the nominal model's; the shift is the calling thread's, so
        it is given at every control step)."""
        if changed and self._nlp is not None:
            self._nlp.forget()
        if self.kernel is not None:
            self.kernel.kernel.set_bias_shift(db)
            if changed:
                self.kernel.invalidate()

    def _build_solver(self, nlp: dict, opts: dict[str, Any], name: str) -> None:
        """The solver of ``nlp`` (the compiled kernel's SQP, casadi ``sqpmethod`` or IPOPT)
        and its argument buffers; forgets the warm start."""
        self.warm_start = None
        self._compiled_loop = False
        if self.solver == "sqp":
            opts = {k: v for k, v in opts.items()
                    if k not in ("ipopt", "grad_f", "jac_g", "hess_lag")}
            nlp, functions = self._nlp.sqp_problem(nlp)
            opts.update(functions)
            sqp = dict(self.sqp_options)
            clip = sqp.pop("hessian_eigen_clip", None)
            loop = sqp.pop("loop")
            self._nlp.eigen_clip = None if clip is None else float(clip)
            if loop == "kernel" and self.kernel is not None:
                from controllers.kernel.kernel_sqp import KernelSQP

                self._solver = KernelSQP(self.kernel, sqp, self.time_budget)
                self._buffer = self._solver.buffers()
                self._compiled_loop = True
                return
            sqp.pop("tol_du_relative", None)   # the kernel's own test: sqpmethod's is absolute
            sqp.pop("reuse_step", None)        # the kernel's own: sqpmethod has no reuse
            opts.update(sqp)
            with quiet_stdout():  # qpOASES prints its licence banner on construction
                self._solver = ca.nlpsol(name, "sqpmethod", nlp, opts)
        else:
            self._solver = ca.nlpsol(name, "ipopt", nlp, opts)
        with quiet_stdout():  # … or when its memory is allocated
            self._buffer = bind_buffers(self._solver)

    def numpy_nlp(self) -> Any:
        """The numpy twin of this problem's derivatives (what the compiled kernel is
        self-tested against): the reference's NLP without a kernel."""
        return self.reference.nlp(None)

    def simulate(self, x_hat: np.ndarray, u_seq: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` of ``eq:gru`` from ``x̂`` under ``u_seq`` (N, m): the compiled
        kernel's plain rollout when there is one, else numpy (:func:`controllers.gru.
        simulate`)."""
        if self.kernel is not None:
            return self.kernel.simulate(np.asarray(x_hat, dtype=float),
                                        np.asarray(u_seq, dtype=float))
        return gru.simulate(self.params, x_hat, u_seq)[0]


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Both ``None``, or equal arrays."""
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))
