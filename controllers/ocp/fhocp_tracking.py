"""The tracking FHOCP: ``eq:optimization`` with an artificial steady state and an offset cost.

    min_{u, u_s}  Σ_{i<N} ‖x_i − x_s‖²_Q + ‖u_i − u_s‖²_R + s ‖x_N − x_s‖²_∞
                  + ‖g(x_s) + d̂ − ȳ‖²_T  [+ Σ_{i<N} ‖u_i − u_{i−1}‖²_S + ‖u_{N−1} − u_s‖²_S]
    s.t.  x_0 = x̂_k,  x_{i+1} = f(x_i, u_i)                                  (eq:gru)
          L(U_o x_i + b_o) + w_L ≤ h − a_i ê_o,k − b_i,  i = 0 … N−1   (eq:optimization-constraint)
          ‖u_i‖∞ ≤ 1,  ‖u_s‖∞ ≤ 1,  ‖x_N − x_s‖∞ ≤ α_c,  x_s = f(x_s, u_s)
          L(U_o x_s + b_o) ≤ h − ẽ_o a_N − b_N − w_L − α_c c_s                (y_s ∈ Y_s)

The paper's FHOCP (:class:`controllers.ocp.fhocp.FHOCP`) with the set-point ``(x̄, ū)`` replaced
by a decision variable: the steady input ``u_s`` and its steady state ``x_s(u_s)``
(:mod:`controllers.ocp.steady_state`), as in MPC for tracking (Limon et al., IEEE TAC 2018). The
requested set-point ``ȳ`` and the output-disturbance estimate ``d̂`` enter the cost only,
through ``r = ȳ − d̂``: any ``r`` gives a feasible problem (the shifted plan with ``u_s``
appended is a candidate), an unreachable or inadmissible one is tracked to the closest
admissible steady state, and with ``d̂`` the static offset goes to zero (offset-free MPC,
Morari & Maeder 2012). One constant terminal radius ``α_c`` replaces ``α(ȳ)`` of
``eq:def-alpha``; the steady outputs are restricted to ``Y_s = {y : α(y) ≥ α_c}``, so that the
paper's recursive-feasibility argument holds with ``x̄ := x_s`` (docs: design/tracking.md).

Single shooting only, solved by the SQP (the compiled kernel with ``HAS_ASS``, its numpy twin
:class:`controllers.ocp.nlp_tracking.TrackingNLP` otherwise) or IPOPT. Every answer is checked
independently: numpy rollout, the steady state recomputed, the output rows, the input box,
the terminal set and ``Y_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers import gru
from controllers.errors import DesignError
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.fhocp_result import FHOCPResult, set_residuals
from controllers.ocp.input_rate import du_cost
from controllers.ocp.solve_status import SolveStatus
from controllers.ocp.steady_state import steady_state

__all__ = ["CONTROL_HORIZON_FRACTION", "DEFAULTS", "LINE_SEARCH", "SQP_OVERRIDES", "US_RATE",
           "Target", "TrackingFHOCP", "default_control_horizon", "steady_output_bounds"]

#: The SQP's line search for the tracking FHOCP (over ``sqpmethod``'s defaults, 3 trials with
#: β = 0.8, the last accepted): a set-point step moves ``u_s`` far, and the short search let
#: the iterates leave the feasible set until a linearisation had no feasible point
#: ("QP_Infeasible", every later step falling back on the candidate: 2 of 40 runs of the
#: plant-uncertainty campaign stuck for 200 steps).
LINE_SEARCH = {"max_iter_ls": 10, "beta": 0.5}
#: The tracking FHOCP's SQP options over :data:`controllers.ocp.solver_settings.SQP_OPTIONS`: the
#: line search above, and the dual test relative to the multipliers
#: (:class:`controllers.kernel.kernel_abi.SqpOptions` ``tol_du_relative``; compiled kernel only).
#: The terminal rows' multipliers reach 10⁵ (``s`` = 32,068 on the four-tank), and rounding
#: then keeps ``‖∇L‖∞`` near 10⁻⁵ at a KKT point (``‖∇L‖∞ / ‖λ‖∞`` ≈ 10⁻¹⁰, infeasibility
#: 10⁻¹⁶): such solves ended as ``Search_Direction_Becomes_Too_Small`` after 3–4 idle
#: iterations (18 of 401 steps of a set-point step pair, 1.1 % of the steps of the
#: plant-uncertainty campaign), reported as failures.
#: ``reuse_step`` = 0.1 (the kernel's derivative reuse, :class:`controllers.kernel.kernel_abi.
#: SqpOptions`; docs: design/tracking.md, "The step time"): the median solve's second
#: iteration keeps the first's Jacobian and Hessian, the step 3.0 → 1.5 ms with the same
#: answers to the stopping test's precision (``benchmarks/bench_derivative_reuse.py``).
SQP_OVERRIDES = {**LINE_SEARCH, "tol_du_relative": True, "reuse_step": 0.1}
#: The tracking law's defaults (docs: design/tracking.md, "Recommendation", "The horizon and
#: the iteration cap"): horizon, offset weight T, Δu weight S, the disturbance filter's β
#: (normalised units) and the SQP's iteration cap. T = 10⁴ rather than the study's 10⁵
#: ("The offset weight"). N = 80 rather than 40, with 40 iterations rather than 15,
#: S = 0.05 and β = 0.3: on the 200 draws of the plant-uncertainty campaign the median
#: summed IAE 0.796 → 0.742× the PI's (h1 598 → 572, h2 703 → 648 m·s), capped solves plus
#: fallbacks 2.48 → 0.28 % of the steps: the slow mode reaches the terminal set within 80
#: samples without the large input moves that capped the SQP at N = 40.
DEFAULTS = {"N": 80, "offset_weight": 1e4, "du_weight": 0.05, "offset_filter": 0.3,
            "max_iter": 40}
#: The default control horizon as a fraction of N (:func:`default_control_horizon`; docs:
#: design/tracking.md, "The control horizon"): on the plant-uncertainty draws M = 10, 20 and
#: 40 of N = 80 track as every input free (median summed IAE ÷ PI 0.772–0.776 against 0.773
#: on 40 draws) with 0–1 capped solves instead of 45, and the step takes half the time.
CONTROL_HORIZON_FRACTION = 0.25


def default_control_horizon(N: int) -> int:
    """The default control horizon of horizon ``N``: ``⌈N / 4⌉`` (20 at N = 80)."""
    return max(1, math.ceil(CONTROL_HORIZON_FRACTION * int(N)))
#: The default largest move of ``u_s`` per step (normalised inputs, range 2): a set-point step
#: otherwise sent the SQP's first iterates so far along the nonlinear ``x_s(u_s)`` that the
#: next linearisation had no feasible point ("QP_Infeasible"), and the solve failed again at
#: every later step from the same candidate (measured: 5 of 200 runs of the guarantee
#: campaign stuck for 300 steps). The candidate keeps ``u_s``, so recursive feasibility holds.
US_RATE = 0.2
#: Largest ``‖f(x_s, u_s) − x_s‖∞`` (numpy) of an accepted steady state (normalised).
XS_CHECK_TOL = 1e-10


def steady_output_bounds(cert: Any, alpha_c: float) -> np.ndarray:
    """Right-hand side of ``Y_s``: ``L y ≤ h − ẽ_o a_N − b_N − w_L − α_c c_s`` (normalised
    outputs ``y``; ``α(y) ≥ α_c`` row by row, ``eq:def-alpha``)."""
    N = cert.N
    return (cert.h - cert.e_tilde * cert.a[N] - cert.b[N] - cert.w_L
            - float(alpha_c) * cert.c_s)


@dataclass(frozen=True)
class Target:
    """The tracking law's request (:class:`~controllers.ocp.requests.SolveRequest`): the target
    ``r = ȳ − d̂``, the candidate (inputs, steady input ``u_s``, Newton's start ``x_s0``),
    ``u_{−1}``, whether to warm start the multipliers and the centre of ``u_s``'s move
    limit (:meth:`TrackingFHOCP.solve_tracking`)."""

    r: np.ndarray
    u_init: np.ndarray
    us_init: np.ndarray
    x_s0: np.ndarray
    u_prev: np.ndarray
    warm: bool
    us_centre: np.ndarray

    def candidate(self, fhocp: TrackingFHOCP, x_hat: np.ndarray, e_o: float, status: str
                  ) -> FHOCPResult:
        return fhocp.check(x_hat, self.u_init, self.us_init, e_o, self.r, self.x_s0,
                           self.u_prev, status)

    def write(self, fhocp: TrackingFHOCP, ins: dict[str, np.ndarray], x_hat: np.ndarray,
              e_o: float) -> None:
        fhocp.write_request(ins, x_hat, e_o, self)

    def check(self, fhocp: TrackingFHOCP, wopt: np.ndarray, pv: np.ndarray,
              x_hat: np.ndarray, e_o: float, status: str) -> FHOCPResult:
        return fhocp.check_request(wopt, pv, x_hat, e_o, self, status)


class TrackingFHOCP(FHOCP):
    """The tracking FHOCP (module docstring): declare, :meth:`setup`, :meth:`solve`.

    Parameters
    ----------
    data : FHOCPData or Certificate
        As :class:`controllers.ocp.fhocp.FHOCP`.
    offset_weight : float or (p,) array
        Diagonal of ``T`` (normalised outputs).
    alpha_c : float
        The terminal set's radius (``α_c > 0``).
    ys_bounds : (q,) array
        Right-hand side of ``Y_s`` (:func:`steady_output_bounds`).
    control_horizon : int, optional
        ``M`` (1 … N): the inputs ``u_0 … u_{M−1}`` are free and ``u_i = u_s`` for
        ``i ≥ M`` (default ``N``: all free). The shifted plan with ``u_s`` appended keeps that
        form, so the candidate, recursive feasibility and the cost decrease are unchanged;
        the decision vector shrinks from ``N m + m + 1`` to ``M m + m + 1`` entries (docs:
        design/tracking.md, "The control horizon").
    **options
        ``solver``, ``sqp_options``, ``kernel``, ``du_weight``, ``ipopt_options``,
        ``time_budget``: as :class:`controllers.ocp.fhocp.FHOCP` (single shooting only).

    Attributes
    ----------
    nw, ng, npar : int
        Sizes of ``w = (u_0 … u_{M−1}, u_s, t)``, of the constraints and of
        ``p = (x̂, x_s0, r[, u_{−1}])``.
    iu, ius, it
        Indices of ``u_i`` in ``w`` (N × m; ``u_s``'s for ``i ≥ M``), of ``u_s`` and of
        ``t``.
    control_horizon : int
        ``M``.
    """

    def __init__(self, data: Any, *, offset_weight: float | np.ndarray, alpha_c: float,
                 ys_bounds: np.ndarray, control_horizon: int | None = None,
                 **options: Any) -> None:
        if options.get("formulation", "single-shooting") != "single-shooting":
            raise DesignError("the tracking FHOCP is single shooting only")
        options["sqp_options"] = {**SQP_OVERRIDES, **(options.get("sqp_options") or {})}
        super().__init__(data, **options)
        T = np.broadcast_to(np.asarray(offset_weight, dtype=float), (self.p,)).copy()
        if not np.all(np.isfinite(T)) or np.any(T <= 0):
            raise DesignError(f"offset weights must be positive, got {T.tolist()}")
        self.offset_weight = T
        self.alpha_c = float(alpha_c)
        if not self.alpha_c > 0:
            raise DesignError(f"alpha_c must be positive, got {alpha_c!r}")
        self.ys_bounds = np.asarray(ys_bounds, dtype=float).reshape(self.q)
        n, m, N, qr = self.n, self.m, self.N, self.qr
        M = N if control_horizon is None else control_horizon
        if isinstance(M, bool) or not isinstance(M, (int, np.integer)) or not 1 <= M <= N:
            raise DesignError(f"control_horizon must be an integer in 1..N = {N}, got "
                              f"{control_horizon!r}")
        self.control_horizon = int(M)
        self.nw = M * m + m + 1
        self.ius = np.arange(M * m, M * m + m)
        self.iu = np.vstack([np.arange(M * m).reshape(M, m),
                             np.tile(self.ius, (N - M, 1))]).astype(int)
        self.it = M * m + m
        self.ng = (N - 1) * qr + 2 * n + qr
        self.npar = 2 * n + self.p + (m if self.has_du else 0)
        self._ys_base = self.ys_bounds - self.Lbo          # Y_s: L U_o x_s <= rhs
        #: ``L d`` of :meth:`set_output_shift` (``None``: the rows as declared)
        self._shift: np.ndarray | None = None
        #: largest move of u_s per step (normalised; None: none), around the candidate's
        #: (``us_centre`` of :meth:`solve_tracking`)
        self.us_rate: float | None = US_RATE
        self._g_for: np.ndarray | None = None   # the bounds _lbg, _ubg were written for
        self._g_rows = self._constraint_rows()
        self._static_layout()

    @property
    def _ys_rhs(self) -> np.ndarray:
        """Right-hand side of ``Y_s`` on ``L U_o x_s`` (shifted by :meth:`set_output_shift`)."""
        return self._ys_base if self._shift is None else self._ys_base - self._shift

    def set_output_shift(self, d: np.ndarray | None) -> None:
        """Constrain ``y + d`` instead of the model's ``y``: every output row
        ``L (U_o x_i + b_o + d) ≤ …`` and ``Y_s`` (the uncertified mode's ``d = d̂``, the
        filtered output mismatch, so that the measured tightening is around the output the
        plant will show); ``None`` restores the rows as declared."""
        self._shift = None if d is None else self.L @ np.asarray(d, dtype=float).reshape(self.p)
        self._g_for = None

    def tightened_bounds(self, e_o: float) -> np.ndarray:
        """:meth:`controllers.ocp.fhocp.FHOCP.tightened_bounds`, minus ``L d`` of
        :meth:`set_output_shift`."""
        bounds = super().tightened_bounds(e_o)
        return bounds if self._shift is None else bounds - self._shift

    def solve(self, *args: Any, **kwargs: Any) -> FHOCPResult:
        """Not this problem's entry point: the set-point is a decision variable here, solve
        with :meth:`solve_tracking` (the target ``r`` and the candidate's ``u_s``)."""
        raise DesignError("TrackingFHOCP has no set-point (x̄, ū) to solve for: call "
                          "solve_tracking(x_hat, e_o, r, u_init, us_init, x_s0)")

    @classmethod
    def from_certificate(cls, cert: Any, **options: Any) -> TrackingFHOCP:
        """The tracking FHOCP of a certificate; ``options`` must hold ``offset_weight`` and
        ``alpha_c`` (``ys_bounds`` defaults to :func:`steady_output_bounds`)."""
        options.setdefault("ys_bounds", steady_output_bounds(cert, options["alpha_c"]))
        return cls(cert, **options)

    def numpy_nlp(self) -> Any:
        from controllers.ocp.nlp_tracking import TrackingNLP

        return TrackingNLP(self, None)

    def setup(self) -> TrackingFHOCP:
        """Build the solver (the compiled kernel's SQP, else casadi's with the numpy twin)."""
        from controllers.kernel.compiled_kernel import for_fhocp
        from controllers.ocp.nlp_tracking import TrackingNLP

        self.kernel = None
        if self.solver == "sqp" and self.kernel_mode == "auto":
            self.kernel, self.kernel_error = for_fhocp(self)
        self._nlp = TrackingNLP(self, self.kernel)
        self._shoot = self._nlp.shoot
        nlp, opts = self._nlp.ipopt_problem(self.ipopt_options, self.time_budget)
        self._xtraj = self._nlp.trajectory
        self._build_solver(nlp, opts, "fhocp_tracking")
        return self

    # -- the answer check ----------------------------------------------------------------
    def tracking_cost(self, x: np.ndarray, u: np.ndarray, u_s: np.ndarray, x_s: np.ndarray,
                      r: np.ndarray, t: float | None = None,
                      u_prev: np.ndarray | None = None) -> float:
        """The cost (module docstring); ``t`` defaults to ``‖x_N − x_s‖∞``."""
        dx = x[: self.N] - x_s
        du = u - u_s
        e = self.params["U_o"] @ x_s + self.params["b_o"] - r
        tN = float(np.max(np.abs(x[self.N] - x_s))) if t is None else t
        J = float(np.vdot(dx @ self.Q, dx) + np.vdot(du @ self.R, du) + self.s * tN ** 2
                  + np.vdot(e * self.offset_weight, e))
        if self.has_du:
            up = u_s if u_prev is None else np.asarray(u_prev, dtype=float)
            J += du_cost(u, up, self.du_weight)
            J += float(np.vdot((u[-1] - u_s) * self.du_weight, u[-1] - u_s))
        return J

    def check(self, x_hat: np.ndarray, u: np.ndarray, u_s: np.ndarray, e_o: float,
              r: np.ndarray, x_s0: np.ndarray, u_prev: np.ndarray | None = None,
              status: str = SolveStatus.CANDIDATE) -> FHOCPResult:
        """Evaluate ``(u, u_s)`` independently of the solver: rollout, ``x_s`` recomputed,
        cost and residuals (output rows, input box, terminal set, ``Y_s``). With a kernel the
        answer check of the solver's answers in one compiled call (:meth:`_check_answer`,
        the exported controller's too; ``u`` in the control horizon's form, its rows from M
        on equal to ``u_s``, as every candidate is), else numpy (Newton for ``x_s``)."""
        u = np.clip(np.asarray(u, dtype=float), -1.0, 1.0)
        u_s = np.clip(np.asarray(u_s, dtype=float), -1.0, 1.0)
        if self.kernel is not None:
            w = np.zeros(self.nw)
            w[self.iu[:self.control_horizon].ravel()] = u[:self.control_horizon].ravel()
            w[self.ius] = u_s
            pv = np.zeros(self.npar)
            self._write_parameters(pv, x_hat, x_s0, r, u_s if u_prev is None else u_prev)
            res = self._check_answer(w, pv, e_o, status)
            res.defect = 0.0   # no solver trajectory to compare with
            return res
        x = self.simulate(np.asarray(x_hat, dtype=float), u)
        x_s, ok = self.steady_state(u_s, x_s0)
        res = FHOCPResult(u=u, x=x, cost=float("nan"), status=status, success=False)
        res.u_s, res.x_s = u_s, x_s
        if not ok:
            res.constraint_violation = res.terminal_violation = float("inf")
            return res
        ub = self.tightened_bounds(e_o)
        lhs = x[: self.N] @ self.LUo.T
        ys = self.LUo @ x_s
        res.constraint_violation = max(0.0, float(np.max(lhs - ub)),
                                       float(np.max(ys - self._ys_rhs)),
                                       float(np.max(np.abs(u))) - 1.0)
        dN = float(np.max(np.abs(x[self.N] - x_s)))
        res.t = dN
        res.terminal_violation = max(0.0, dN - self.alpha_c)
        res.active = (int(np.sum(lhs[1:] - ub[1:] > -1e-6)) + int(dN - self.alpha_c > -1e-6)
                      + int(np.sum(np.abs(u) > 1 - 1e-6)))
        res.cost = self.tracking_cost(x, u, u_s, x_s, r, u_prev=u_prev)
        return res

    def steady_state(self, u_s: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, bool]:
        """``(x_s(u_s), ok)``: the compiled kernel's Newton when there is one (its answer a
        fixed point of numpy's ``eq:gru`` to ``XS_CHECK_TOL``), else numpy's."""
        if self.kernel is not None:
            x_s = self.kernel.steady_state(u_s, x0)
            if x_s is not None and float(np.max(np.abs(
                    gru.step(self.params, x_s, u_s) - x_s))) <= XS_CHECK_TOL:
                return x_s, True
            return np.full(self.n, np.nan), False
        x_s, _, ok = steady_state(self.params, u_s, x0)
        return x_s, ok

    # -- solving -------------------------------------------------------------------------
    def solve_tracking(self, x_hat: np.ndarray, e_o: float, r: np.ndarray,
                       u_init: np.ndarray, us_init: np.ndarray, x_s0: np.ndarray,
                       u_prev: np.ndarray | None = None, warm: bool = True,
                       us_centre: np.ndarray | None = None) -> FHOCPResult:
        """Solve at ``x̂`` with ``ê_o`` for the target ``r = ȳ − d̂`` (normalised): the
        :class:`Target` request in :meth:`~controllers.ocp.fhocp.FHOCP.solve_request`.

        Parameters
        ----------
        u_init, us_init : arrays
            Initial inputs (N, m) and steady input (m,): the candidate (the previous plan
            shifted with ``u_s`` appended, and ``u_s``).
        x_s0 : (n,) array
            Newton's start for ``x_s(u_s)`` (the steady state of ``us_init``).
        u_prev : (m,) array, optional
            ``u_{−1}`` of the input-rate term (``None``: ``us_init``).
        warm : bool
            Warm start the multipliers from the previous solve, shifted by one stage.
        us_centre : (m,) array, optional
            Centre of the move limit on ``u_s`` (:attr:`us_rate`): the candidate's ``u_s``,
            so that the candidate stays feasible (default ``us_init``).
        """
        # np.minimum/maximum: np.clip's dispatch costs ~10 µs a call on this hot path
        us_init = np.minimum(np.maximum(np.asarray(us_init, dtype=float).reshape(self.m),
                                        -1.0), 1.0)
        u_init = np.minimum(np.maximum(np.asarray(u_init, dtype=float).reshape(
            self.N, self.m), -1.0), 1.0)
        up = us_init if u_prev is None else np.asarray(u_prev, dtype=float).reshape(self.m)
        request = Target(np.asarray(r, dtype=float).reshape(self.p), u_init, us_init,
                         np.asarray(x_s0, dtype=float).reshape(self.n), up, warm,
                         us_init if us_centre is None else np.asarray(us_centre, dtype=float))
        return self.solve_request(x_hat, e_o, request)

    def write_request(self, ins: dict[str, np.ndarray], x_hat: np.ndarray, e_o: float,
                      request: Target) -> None:
        """The solver's buffers for a :class:`Target`: ``p = (x̂, x_s0, r[, u_{−1}])``, the
        bounds (the tightened rows, ``Y_s``, the move limit on ``u_s``), the candidate as
        the initial guess with ``t`` its terminal gap, and the multipliers shifted by one
        stage (``warm``) or zeros."""
        pv = ins["p"]
        self._write_parameters(pv, x_hat, request.x_s0, request.r, request.u_prev)
        self._write_bounds(ins, e_o)
        if self.us_rate is not None:   # the steady input moves at most us_rate per step
            c = request.us_centre
            ins["lbx"][self.ius] = np.maximum(c - self.us_rate, -1.0)
            ins["ubx"][self.ius] = np.minimum(c + self.us_rate, 1.0)
        w0 = ins["x0"]
        w0[self.iu.ravel()] = request.u_init.ravel()
        w0[self.ius] = np.minimum(np.maximum(request.us_init, ins["lbx"][self.ius]),
                                  ins["ubx"][self.ius])
        if self.kernel is not None:   # the rollout stays cached for the solve
            gap = self.kernel.terminal_gap(w0, pv)
        else:
            gap = float(np.max(np.abs(self.simulate(x_hat, request.u_init)[-1]
                                      - request.x_s0)))
        w0[self.it] = min(max(gap, 1e-6), self.alpha_c)
        if request.warm and self._warm is not None and self.warm_duals:
            ins["lam_x0"][:] = self._warm["lam_x"][self._perm_x]
            ins["lam_g0"][:] = self._warm["lam_g"][self._perm_g]
        else:
            ins["lam_x0"][:] = 0.0
            ins["lam_g0"][:] = 0.0

    def check_request(self, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray, e_o: float,
                      request: Target, status: str) -> FHOCPResult:
        """The independent check of the solver's answer ``wopt`` to a :class:`Target`: in
        one compiled call with a kernel (:meth:`_check_answer`), else :meth:`check` with the
        defect against the solver's own trajectory."""
        if self.kernel is not None:
            return self._check_answer(wopt, pv, e_o, status)
        res = self.check(x_hat, wopt[self.iu], wopt[self.ius], e_o, request.r, request.x_s0,
                         request.u_prev, status)
        res.defect = float(np.max(np.abs(self._xtraj(wopt, pv) - res.x)))
        return res

    def _check_answer(self, w: np.ndarray, p: np.ndarray, e_o: float, status: str
                      ) -> FHOCPResult:
        """:meth:`check` of the solver's answer ``w`` in one compiled call (the kernel's
        plain rollout and a fixed-point test of its ``x_s``, apart from the solver's
        derivatives: :meth:`controllers.kernel.kernel_lib.Workspace.assess_w`), plus the defect
        against the solver's own trajectory."""
        u, x, out, x_s = self.kernel.assess_w(w, p, self.tightened_bounds(e_o), self.alpha_c)
        res = FHOCPResult(u=u, x=x, cost=out.cost, status=status, success=False,
                          t=out.terminal_distance, defect=out.defect)
        res.u_s, res.x_s = np.minimum(np.maximum(w[self.ius], -1.0), 1.0), x_s
        if not out.steady_residual <= XS_CHECK_TOL:   # NaN: Newton did not converge
            res.x_s = np.full(self.n, np.nan)
            res.constraint_violation = res.terminal_violation = float("inf")
            return res
        set_residuals(res, out, self.alpha_c)
        res.constraint_violation = max(res.constraint_violation,
                                       float(np.max(self.LUo @ x_s - self._ys_rhs)))
        return res

    def _write_parameters(self, pv: np.ndarray, x_hat: Any, x_s0: Any, r: Any,
                          u_prev: Any) -> None:
        """``p = (x̂, x_s0, r[, u_{−1}])`` into ``pv`` (``u_{−1}`` only with the input-rate
        term)."""
        n = self.n
        pv[:n], pv[n:2 * n], pv[2 * n:2 * n + self.p] = x_hat, x_s0, r
        if self.has_du:
            pv[2 * n + self.p:] = u_prev

    def _write_bounds(self, ins: dict[str, np.ndarray], e_o: float) -> None:
        """Variable and constraint bounds of one solve (the tightened rows for ``ê_o``)."""
        ins["lbx"][:] = self._lbx
        ins["ubx"][:] = self._ubx
        bounds = self.tightened_bounds(e_o)
        if self._g_for is not bounds:
            up_pos, up_idx, lo_pos, lo_idx = self._g_rows
            flat = bounds.ravel()
            self._ubg[up_pos] = flat[up_idx]
            self._lbg[lo_pos] = -flat[lo_idx]
            r0 = (self.N - 1) * self.qr + 2 * self.n      # the Y_s rows
            rhs = self._ys_rhs
            self._ubg[r0:] = rhs[self.pair_up]
            self._lbg[r0:] = np.where(self.pair_lo >= 0, -rhs[np.maximum(self.pair_lo, 0)],
                                      -np.inf)
            self._g_for = bounds
        ins["lbg"][:] = self._lbg
        ins["ubg"][:] = self._ubg

    def _constraint_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The static constraint bounds (terminal and ``Y_s`` rows, into ``_lbg``/``_ubg``)
        and where the tightened bounds (N×q, rows i ≥ 1) go: ``(up_pos, up_idx, lo_pos,
        lo_idx)``, ``ubg[up_pos] = bounds.flat[up_idx]``, ``lbg[lo_pos] = −bounds.flat[
        lo_idx]`` (the output rows' paired bounds; unpaired lower bounds stay −∞)."""
        N, qr, n, q = self.N, self.qr, self.n, self.q
        lbg = np.full(self.ng, -np.inf)
        ubg = np.full(self.ng, np.inf)
        r0 = (N - 1) * qr
        ubg[r0:r0 + n] = 0.0
        lbg[r0 + n:r0 + 2 * n] = 0.0                  # the Y_s rows: _write_bounds
        self._lbg, self._ubg = lbg, ubg
        stage = np.arange(1, N)[:, None] * q
        up_idx = (stage + self.pair_up[None, :]).ravel()
        has_lo = np.broadcast_to(self.pair_lo >= 0, (N - 1, qr)).ravel()
        lo_idx = (stage + np.maximum(self.pair_lo, 0)[None, :]).ravel()
        pos = np.arange(r0)
        return pos, up_idx, pos[has_lo], lo_idx[has_lo]

    def _static_layout(self) -> None:
        """The variable bounds and the permutations that shift ``w`` and the multipliers by
        one stage (the warm start)."""
        lbx = np.full(self.nw, -1.0)
        ubx = np.full(self.nw, 1.0)
        lbx[self.it], ubx[self.it] = 0.0, self.alpha_c
        self._lbx, self._ubx = lbx, ubx
        px = np.arange(self.nw)
        free = self.iu[:self.control_horizon]
        px[free[:-1].ravel()] = free[1:].ravel()
        if self.control_horizon < self.N:   # the last free input takes u_s's value
            px[free[-1]] = self.ius
        self._perm_x = px
        N, qr = self.N, self.qr
        pg = np.arange(self.ng)
        if N > 1:
            blk = np.arange((N - 1) * qr).reshape(N - 1, qr)
            pg[: (N - 1) * qr] = np.vstack([blk[1:], blk[-1:]]).ravel()
        self._perm_g = pg
