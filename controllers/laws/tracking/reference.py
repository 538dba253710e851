"""The tracking law's reference: an artificial steady state and an offset cost in the FHOCP.

    min_{u, u_s}  Σ_{i<N} ‖x_i − x_s‖²_Q + ‖u_i − u_s‖²_R + s ‖x_N − x_s‖²_∞
                  + ‖g(x_s) + d̂ − ȳ‖²_T  [+ Σ_{i<N} ‖u_i − u_{i−1}‖²_S + ‖u_{N−1} − u_s‖²_S]
    s.t.  x_0 = x̂_k,  x_{i+1} = f(x_i, u_i)                                  (eq:gru)
          L(U_o x_i + b_o) + w_L ≤ h − a_i ê_o,k − b_i,  i = 0 … N−1   (eq:optimization-constraint)
          ‖u_i‖∞ ≤ 1,  ‖u_s‖∞ ≤ 1,  ‖x_N − x_s‖∞ ≤ α_c,  x_s = f(x_s, u_s)
          L(U_o x_s + b_o) ≤ h − ẽ_o a_N − b_N − w_L − α_c c_s                (y_s ∈ Y_s)

The :class:`~controllers.ocp.reference.Reference` of the tracking MPC
(:mod:`controllers.laws.tracking.mpc`): the FHOCP (:class:`controllers.ocp.fhocp.FHOCP`) with
the set-point ``(x̄, ū)`` of the paper's law replaced by a decision variable: the steady
input ``u_s`` and its steady state ``x_s(u_s)`` (:mod:`controllers.ocp.steady_state`), as in
MPC for tracking (Limon et al., IEEE TAC 2018). The
requested set-point ``ȳ`` and the output-disturbance estimate ``d̂`` enter the cost only,
through ``r = ȳ − d̂``: any ``r`` gives a feasible problem (the shifted plan with ``u_s``
appended is a candidate), an unreachable or inadmissible one is tracked to the closest
admissible steady state, and with ``d̂`` the static offset goes to zero (offset-free MPC,
Morari & Maeder 2012). One constant terminal radius ``α_c`` replaces ``α(ȳ)`` of
``eq:def-alpha``; the steady outputs are restricted to ``Y_s = {y : α(y) ≥ α_c}``, so that the
paper's recursive-feasibility argument holds with ``x̄ := x_s`` (docs: design/tracking.md).

Single shooting only, solved by the SQP (the compiled kernel with ``HAS_ASS``, its numpy twin
:class:`controllers.laws.tracking.nlp.TrackingNLP` otherwise) or IPOPT. Every answer is checked
independently: numpy rollout, the steady state recomputed, the output rows, the input box,
the terminal set and ``Y_s``. Build it as ``FHOCP.from_certificate(cert,
reference=ArtificialSteadyState(offset_weight, alpha_c))`` and solve with ``fhocp.solve(x̂,
ê_o, r, u_init, us_init, x_s0)`` (:meth:`ArtificialSteadyState.request`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers import gru
from controllers.errors import DesignError
from controllers.laws.tracking.layout import TrackingLayout
from controllers.ocp.fhocp_result import FHOCPResult, plan_residuals, set_residuals
from controllers.ocp.input_rate import du_cost
from controllers.ocp.reference import ServesOne
from controllers.ocp.solve_status import SolveStatus
from controllers.ocp.steady_state import steady_state

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = [
    "CONTROL_HORIZON_FRACTION",
    "LINE_SEARCH",
    "SQP_OVERRIDES",
    "US_RATE",
    "ArtificialSteadyState",
    "Target",
    "default_control_horizon",
    "steady_output_bounds",
]

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
    """One solve's request of the tracking law (:meth:`ArtificialSteadyState.request`): the
    target ``r = ȳ − d̂``, the candidate (inputs, steady input ``u_s``, Newton's start ``x_s0``),
    ``u_{−1}``, whether to warm start the multipliers and the centre of ``u_s``'s move
    limit."""

    r: np.ndarray
    u_init: np.ndarray
    us_init: np.ndarray
    x_s0: np.ndarray
    u_prev: np.ndarray
    warm: bool
    us_centre: np.ndarray


class ArtificialSteadyState(TrackingLayout, ServesOne):
    """The tracking law's part of the FHOCP (module docstring), a
    :class:`~controllers.ocp.reference.Reference`.

    Parameters
    ----------
    offset_weight : float or (p,) array
        Diagonal of ``T`` (normalised outputs).
    alpha_c : float
        The terminal set's radius (``α_c > 0``).
    ys_bounds : (q,) array, optional
        Right-hand side of ``Y_s``; default :func:`steady_output_bounds` of the FHOCP's
        certificate.
    control_horizon : int, optional
        ``M`` (1 … N): the inputs ``u_0 … u_{M−1}`` are free and ``u_i = u_s`` for
        ``i ≥ M`` (default ``N``: all free). The shifted plan with ``u_s`` appended keeps that
        form, so the candidate, recursive feasibility and the cost decrease are unchanged;
        the decision vector shrinks from ``N m + m + 1`` to ``M m + m + 1`` entries (docs:
        design/tracking.md, "The control horizon").

    Attributes
    ----------
    nw, ng, npar : int
        Sizes of ``w = (u_0 … u_{M−1}, u_s, t)``, of the constraints and of
        ``p = (x̂, x_s0, r[, u_{−1}])`` (once attached to an FHOCP).
    iu, ius, it
        Indices of ``u_i`` in ``w`` (N × m; ``u_s``'s for ``i ≥ M``), of ``u_s`` and of
        ``t``.
    us_rate : float or None
        Largest move of ``u_s`` per step (normalised; ``None``: none), around the request's
        ``us_centre``; default :data:`US_RATE`.
    perm_x, perm_g : int arrays
        The permutations that shift ``w`` and the multipliers by one stage (warm start).
    """

    name = "tracking"
    formulations = ("single-shooting",)
    sqp_overrides = SQP_OVERRIDES

    def __init__(self, offset_weight: float | np.ndarray, alpha_c: float,
                 ys_bounds: np.ndarray | None = None,
                 control_horizon: int | None = None) -> None:
        self.alpha_c = float(alpha_c)
        if not self.alpha_c > 0:
            raise DesignError(f"alpha_c must be positive, got {alpha_c!r}")
        self._offset_weight = offset_weight
        self._ys_bounds = ys_bounds
        self._control_horizon = control_horizon
        self.us_rate: float | None = US_RATE

    def attach(self, fhocp: FHOCP, data: Any) -> None:
        """Serve ``fhocp``: ``T`` on its outputs, ``Y_s`` (of ``data``, a certificate, when
        not given), the control horizon and the layout."""
        self._refuse_another(fhocp)
        T = np.broadcast_to(np.asarray(self._offset_weight, dtype=float), (fhocp.p,)).copy()
        if not np.all(np.isfinite(T)) or np.any(T <= 0):
            raise DesignError(f"offset weights must be positive, got {T.tolist()}")
        self.offset_weight = T
        if self._ys_bounds is None:
            if not hasattr(data, "e_tilde"):
                raise DesignError("ys_bounds is needed for an FHOCP built without a "
                                  "certificate (steady_output_bounds)")
            self._ys_bounds = steady_output_bounds(data, self.alpha_c)
        self.ys_bounds = np.asarray(self._ys_bounds, dtype=float).reshape(fhocp.q)
        N = fhocp.N
        M = N if self._control_horizon is None else self._control_horizon
        if isinstance(M, bool) or not isinstance(M, (int, np.integer)) or not 1 <= M <= N:
            raise DesignError(f"control_horizon must be an integer in 1..N = {N}, got "
                              f"{self._control_horizon!r}")
        self.control_horizon = int(M)
        self.fhocp = fhocp   # valid for it: it serves it from here on
        self._layout(fhocp)

    @property
    def ys_rhs(self) -> np.ndarray:
        """Right-hand side of ``Y_s`` on ``L U_o x_s`` (narrowed by the operator's limits,
        :attr:`~controllers.ocp.fhocp.FHOCP.narrowing`, ``eq:operator-rows``; shifted by
        the FHOCP's :meth:`~controllers.ocp.fhocp.FHOCP.set_output_shift`)."""
        fh = self._fh
        base = self.ys_base if fh.narrowing is None else self.ys_base - fh.narrowing
        return base if fh.output_shift is None else base - fh.output_shift

    def kernel_terms(self) -> dict[str, Any]:
        """The kernel's artificial steady state (``HAS_ASS``) and control horizon."""
        return {"offset_weight": self.offset_weight, "control_horizon": self.control_horizon}

    def nlp(self, kernel: Any) -> Any:
        from controllers.laws.tracking.nlp import TrackingNLP

        return TrackingNLP(self._fh, kernel)

    # -- one solve -----------------------------------------------------------------------
    def request(self, r: np.ndarray, u_init: np.ndarray, us_init: np.ndarray,
                x_s0: np.ndarray, u_prev: np.ndarray | None = None, warm: bool = True,
                us_centre: np.ndarray | None = None) -> Target:
        """The request of :meth:`controllers.ocp.fhocp.FHOCP.solve`: the target
        ``r = ȳ − d̂`` (normalised) from the candidate.

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
        fh = self._fh
        # np.minimum/maximum: np.clip's dispatch costs ~10 µs a call on this hot path
        us_init = np.minimum(np.maximum(np.asarray(us_init, dtype=float).reshape(fh.m),
                                        -1.0), 1.0)
        u_init = fh.prefix.impose(np.minimum(np.maximum(np.asarray(u_init, dtype=float).reshape(
            fh.N, fh.m), -1.0), 1.0))
        up = us_init if u_prev is None else np.asarray(u_prev, dtype=float).reshape(fh.m)
        return Target(np.asarray(r, dtype=float).reshape(fh.p), u_init, us_init,
                      np.asarray(x_s0, dtype=float).reshape(fh.n), up, warm,
                      us_init if us_centre is None else np.asarray(us_centre, dtype=float))

    def check_answer(self, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray, e_o: float,
                     request: Target, status: str) -> FHOCPResult:
        """In one compiled call with a kernel (:meth:`_check_compiled`), else
        :meth:`evaluate` with the defect against the solver's own trajectory."""
        fh = self._fh
        if fh.kernel is not None:
            return self._check_compiled(wopt, pv, e_o, status, fh.softening)
        res = self.evaluate(x_hat, wopt[self.iu], wopt[self.ius], e_o, request.r,
                            request.x_s0, request.u_prev, status, soft=fh.softening)
        res.defect = float(np.max(np.abs(fh.solver_trajectory(wopt, pv) - res.x)))
        return res

    def fallback(self, x_hat: np.ndarray, e_o: float, request: Target,
                 status: str) -> FHOCPResult:
        return self.evaluate(x_hat, request.u_init, request.us_init, e_o, request.r,
                             request.x_s0, request.u_prev, status)

    # -- the answer check ----------------------------------------------------------------
    def cost(self, x: np.ndarray, u: np.ndarray, u_s: np.ndarray, x_s: np.ndarray,
             r: np.ndarray, t: float | None = None, u_prev: np.ndarray | None = None
             ) -> float:
        """The cost (module docstring); ``t`` defaults to ``‖x_N − x_s‖∞``."""
        fh = self._fh
        dx = x[: fh.N] - x_s
        du = u - u_s
        e = fh.params["U_o"] @ x_s + fh.params["b_o"] - r
        tN = float(np.max(np.abs(x[fh.N] - x_s))) if t is None else t
        J = float(np.vdot(dx @ fh.Q, dx) + np.vdot(du @ fh.R, du) + fh.s * tN ** 2
                  + np.vdot(e * self.offset_weight, e))
        if fh.has_du:
            up = u_s if u_prev is None else np.asarray(u_prev, dtype=float)
            J += du_cost(u, up, fh.du_weight)
            J += float(np.vdot((u[-1] - u_s) * fh.du_weight, u[-1] - u_s))
        return J

    def evaluate(self, x_hat: np.ndarray, u: np.ndarray, u_s: np.ndarray, e_o: float,
                 r: np.ndarray, x_s0: np.ndarray, u_prev: np.ndarray | None = None,
                 status: str = SolveStatus.CANDIDATE, *, soft: bool = False) -> FHOCPResult:
        """Evaluate ``(u, u_s)`` independently of the solver: rollout, ``x_s`` recomputed,
        cost and residuals (output rows, input box, terminal set, ``Y_s``; ``soft``: the
        softened phase's answer, :func:`~controllers.ocp.fhocp_result.route_softened`). With
        a kernel the answer check of the solver's answers in one compiled call
        (:meth:`_check_compiled`,
        the exported controller's too; ``u`` in the control horizon's form, its rows from M
        on equal to ``u_s``, as every candidate is), else numpy (Newton for ``x_s``)."""
        fh = self._fh
        u = np.clip(np.asarray(u, dtype=float), -1.0, 1.0)
        u_s = np.clip(np.asarray(u_s, dtype=float), -1.0, 1.0)
        if fh.kernel is not None:
            w = np.zeros(self.nw)
            w[self.iu[:self.control_horizon].ravel()] = u[:self.control_horizon].ravel()
            w[self.ius] = u_s
            pv = np.zeros(self.npar)
            self._write_parameters(pv, x_hat, x_s0, r, u_s if u_prev is None else u_prev)
            res = self._check_compiled(w, pv, e_o, status, soft)
            res.defect = 0.0   # no solver trajectory to compare with
            return res
        x = fh.simulate(np.asarray(x_hat, dtype=float), u)
        x_s, ok = self.steady_state(u_s, x_s0)
        res = FHOCPResult(u=u, x=x, cost=float("nan"), status=status, success=False)
        res.u_s, res.x_s = u_s, x_s
        if not ok:
            res.constraint_violation = res.terminal_violation = float("inf")
            return res
        self._residuals(res, x, x_s, e_o, soft)
        res.cost = self.plan_cost(x, u, u_s, x_s, r, e_o, u_prev)
        return res

    def plan_cost(self, x: np.ndarray, u: np.ndarray, u_s: np.ndarray, x_s: np.ndarray,
                  r: np.ndarray, e_o: float, u_prev: np.ndarray | None = None) -> float:
        """The cost of a plan (:meth:`cost` with ``t = ‖x_N − x_s‖∞``); softened
        (:mod:`controllers.ocp.soft`): ``t = min(‖x_N − x_s‖∞, α_c)`` and the penalty of the
        plan's smallest slacks (the output rows and ``Y_s``'s)."""
        fh = self._fh
        dN = float(np.max(np.abs(x[fh.N] - x_s)))
        sl = fh.soft_design
        if sl is None:
            return self.cost(x, u, u_s, x_s, r, dN, u_prev)
        eps = sl.of_plan(self._excess(x, x_s, e_o), dN, self.alpha_c)
        return (self.cost(x, u, u_s, x_s, r, sl.plan_terminal(dN, self.alpha_c), u_prev)
                + sl.penalty(eps))

    def _excess(self, x: np.ndarray, x_s: np.ndarray, e_o: float) -> np.ndarray:
        """The rows' excess of a plan: stages ``1 … N−1`` then ``Y_s`` (N × q)."""
        fh = self._fh
        return np.vstack([x[1:fh.N] @ fh.LUo.T - fh.tightened_bounds(e_o)[1:],
                          fh.LUo @ x_s - self.ys_rhs])

    def steady_bounds(self, e_o: float) -> np.ndarray:
        """The tightened bounds with ``Y_s``'s right-hand side as one more row ((N + 1) × q:
        what a softened kernel prices)."""
        return np.vstack([self._fh.tightened_bounds(e_o), self.ys_rhs])

    def _residuals(self, res: FHOCPResult, x: np.ndarray, x_s: np.ndarray, e_o: float,
                   soft: bool) -> None:
        """:func:`~controllers.ocp.fhocp_result.plan_residuals` around ``x_s`` with
        ``α_c``, and ``Y_s``'s violation, into ``res`` (``res.t``: ``‖x_N − x_s‖∞``)."""
        fh = self._fh
        res.t = plan_residuals(res, x, fh.LUo, fh.tightened_bounds(e_o), x_s, self.alpha_c,
                               soft)
        self._steady_rows(res, x_s, soft)

    def _steady_rows(self, res: FHOCPResult, x_s: np.ndarray, soft: bool) -> None:
        """``Y_s``'s excess at ``x_s`` into ``res``: a violation, or for the softened phase's
        answer (``soft``, :mod:`controllers.ocp.soft`) part of ``res.softened``."""
        excess = float(np.max(self._fh.LUo @ x_s - self.ys_rhs))
        if soft:
            res.softened = max(res.softened, excess)
        else:
            res.constraint_violation = max(res.constraint_violation, excess)

    def steady_state(self, u_s: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, bool]:
        """``(x_s(u_s), ok)``: the compiled kernel's Newton when there is one (its answer a
        fixed point of numpy's ``eq:gru`` to ``XS_CHECK_TOL``), else numpy's."""
        fh = self._fh
        if fh.kernel is not None:
            x_s = fh.kernel.steady_state(u_s, x0)
            if x_s is not None and float(np.max(np.abs(
                    gru.step(fh.params, x_s, u_s) - x_s))) <= XS_CHECK_TOL:
                return x_s, True
            return np.full(fh.n, np.nan), False
        x_s, _, ok = steady_state(fh.params, u_s, x0)
        return x_s, ok

    def _check_compiled(self, w: np.ndarray, p: np.ndarray, e_o: float, status: str,
                        soft: bool = False) -> FHOCPResult:
        """:meth:`evaluate` of the solver's answer ``w`` in one compiled call (the kernel's
        plain rollout and a fixed-point test of its ``x_s``, apart from the solver's
        derivatives: :meth:`controllers.kernel.kernel_lib.Workspace.assess_w`), plus the defect
        against the solver's own trajectory."""
        fh = self._fh
        # softened: Y_s's right-hand side as one more row, the kernel prices its excess
        bounds = self.steady_bounds(e_o) if fh.soft else fh.tightened_bounds(e_o)
        u, x, out, x_s = fh.kernel.assess_w(w, p, bounds, self.alpha_c)
        res = FHOCPResult(u=u, x=x, cost=out.cost, status=status, success=False,
                          t=out.terminal_distance, defect=out.defect)
        res.u_s, res.x_s = np.minimum(np.maximum(w[self.ius], -1.0), 1.0), x_s
        if not out.steady_residual <= XS_CHECK_TOL:   # NaN: Newton did not converge
            res.x_s = np.full(fh.n, np.nan)
            res.constraint_violation = res.terminal_violation = float("inf")
            return res
        set_residuals(res, out, self.alpha_c, soft)
        self._steady_rows(res, x_s, soft)
        return res
