"""The FHOCP of the robust MPC, ``eq:optimization`` (Definition 5), in casadi.

    min_u  Σ_{i=0}^{N-1} ‖x_i − x̄‖²_Q + ‖u_i − ū‖²_R  +  s ‖x_N − x̄‖²_∞
    s.t.   x_0 = x̂_k,  x_{i+1} = f(x_i, u_i)                          (eq:gru)
           L(U_o x_i + b_o) + w_L ≤ h − a_i ê_o,k − b_i,  i = 0 … N−1  (eq:optimization-constraint)
           ‖u_i‖∞ ≤ 1                                                   (eq:input-constraint)
           ‖x_N − x̄‖∞ ≤ α                                               (eq:terminal_constraint)

(the paper's ``x_N + x̄`` in the terminal cost is a typo: it is ``x_N − x̄``). The ∞-norm term is
written with an epigraph variable ``t``: ``−t ≤ x_N − x̄ ≤ t`` element-wise, cost ``s t²``,
``0 ≤ t ≤ α`` (so the terminal set is a bound on ``t``). Everything that depends on the
set-point or on time (x̂, x̄, ū, α, ê_o and the tightened bounds) is a parameter or a bound, so
the problem is built once.

Two formulations of the same problem:

``"single-shooting"`` (default, fast)
    Decision variables ``u_0 … u_{N−1}, t`` only (31 for N = 15, m = 2). The states, their
    sensitivities and the exact Hessian of the Lagrangian come from
    :class:`controllers.shooting.GRUShooting` (dense numpy products, checked against casadi AD
    of :func:`controllers.gru.step`) and reach the solver through zero-copy casadi callbacks.
    Default solver: casadi ``sqpmethod`` (:data:`SQP_OPTIONS`: exact Hessian with its
    eigenvalues clipped at 1e-2, dense active-set QPs by qpOASES, ℓ1-merit line search, at
    most 15 iterations), warm started with the primal and dual solution shifted by one stage;
    ``solver="ipopt"`` (or giving ``ipopt_options``) uses IPOPT instead
    (``warm_start_init_point``, small ``mu_init``, adaptive barrier, ``tol`` 1e-6, 15
    iterations). No wall-clock limit by default (deterministic). The ``i = 0`` constraint
    involves only ``x̂`` (no decision variable): it is checked before the solve, and a
    violated one is reported as ``"infeasible_x0"`` without calling the solver.
    The README (section "Robust MPC") lists the alternatives measured (Gauss-Newton Hessian,
    SX/MX graphs, C code generation, IPOPT vs SQP) and why they won or lost.

``"multiple-shooting"`` (the plain baseline, what do-mpc builds)
    States and inputs are all decision variables in stage order with the dynamics as equality
    constraints, exact Hessian, IPOPT defaults, primal warm start only. Used by the benchmark
    as the speed baseline and by the tests as a tight reference.

Every answer is checked independently of the solver's status: the inputs are rolled out with
numpy (:func:`controllers.gru.simulate`) and the constraint violations, the terminal-set
violation and the defect between the solver's and numpy's trajectories are measured (see
:class:`FHOCPResult`). An answer is accepted only when the solver reports success AND these
residuals are within tolerance.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from controllers import gru

#: Residual tolerances of an accepted answer (normalised units).
FEAS_TOL = 1e-7
DEFECT_TOL = 1e-8

#: IPOPT options of the fast formulation (chosen by measurement; README, "Robust MPC").
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

#: Options of the default solver (``solver="sqp"``, casadi ``sqpmethod``), chosen by
#: measurement (README, "Robust MPC"): the exact Hessian from the same callbacks, with its
#: eigenvalues clipped at ``hessian_eigen_clip`` (numpy ``eigh`` in the callback; our key,
#: not passed to casadi) for the QP. Rejected: sqpmethod's ``regularize`` (Gershgorin shift)
#: makes the iterates crawl; a 1e-7 clipping margin gives steps the ℓ1-merit line search
#: rejects; its ``eigen-clip`` needs many Jacobi sweeps (at the default 200 it aborts without
#: a status). Dense active-set QPs by ``qpOASES`` (``daqp`` stalled at zero steps near
#: regulation: 157 fallbacks on leak_tank1); ``tol_pr`` below the residual check's 1e-7; the
#: same 15-iteration cap as IPOPT.
SQP_OPTIONS: dict[str, Any] = {
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


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence the C-level standard output (file descriptor 1) for the block."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class _NumpyFunction(ca.Callback):
    """A casadi function evaluated by numpy code (dense inputs, given output sparsity)."""

    def __init__(self, name: str, fn: Any, sp_in: list, sp_out: list, names_in: list[str],
                 names_out: list[str]) -> None:
        ca.Callback.__init__(self)
        self._fn, self._sp_in, self._sp_out = fn, sp_in, sp_out
        self._names_in, self._names_out = names_in, names_out
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._sp_in)

    def get_n_out(self) -> int:
        return len(self._sp_out)

    def get_sparsity_in(self, i: int) -> Any:
        return self._sp_in[i]

    def get_sparsity_out(self, i: int) -> Any:
        return self._sp_out[i]

    def get_name_in(self, i: int) -> str:
        return self._names_in[i]

    def get_name_out(self, i: int) -> str:
        return self._names_out[i]

    def has_eval_buffer(self) -> bool:
        return True

    def eval_buffer(self, arg: list, res: list) -> int:
        # zero-copy views: converting numpy ↔ DM costs ~0.2 ms per 76×31 matrix
        ins = [np.zeros(sp.nnz()) if a is None else np.frombuffer(a, dtype=float,
                                                                    count=sp.nnz())
               for a, sp in zip(arg, self._sp_in, strict=True)]
        outs = self._fn(*ins)
        for r, o in zip(res, outs, strict=True):
            if r is not None:
                np.frombuffer(r, dtype=float)[:] = np.ravel(o, order="F")
        return 0


class FHOCP:
    """The FHOCP ``eq:optimization``: declare, :meth:`setup` once, :meth:`solve` each step.

    Parameters
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
    formulation : {"single-shooting", "multiple-shooting"}
    ipopt_options : dict, optional
        Overrides of the IPOPT options (``FAST_IPOPT_OPTIONS`` for single shooting, IPOPT
        defaults for multiple shooting).
    warm_duals : bool
        Warm start the multipliers too (single shooting default; off for the plain baseline).
    solver : {"sqp", "ipopt"}, optional
        NLP solver of the single-shooting formulation: ``"sqp"`` (casadi ``sqpmethod``, exact
        convexified Hessian, dense qpOASES QPs, :data:`SQP_OPTIONS`) or ``"ipopt"``
        (:data:`FAST_IPOPT_OPTIONS`). Default: ``"sqp"``, or ``"ipopt"`` when
        ``ipopt_options`` are given or for multiple shooting (always IPOPT).
    sqp_options : dict, optional
        Overrides of :data:`SQP_OPTIONS`.
    time_budget : float, optional
        Wall-time budget of one single-shooting solve [s]; past it the next IPOPT iteration
        is stopped by an iteration callback (status ``"time_budget_exceeded"``) so that the
        controller applies its fallback in time. Off by default: a wall-clock limit makes
        closed-loop results depend on the machine; the default bound is deterministic
        (``max_iter`` in :data:`FAST_IPOPT_OPTIONS`).
    """

    def __init__(self, params: Mapping[str, np.ndarray], N: int, Q: np.ndarray, R: np.ndarray,
                 L: np.ndarray, h: np.ndarray, w_L: np.ndarray, a: np.ndarray, b: np.ndarray,
                 s: float, *, formulation: str = "single-shooting",
                 ipopt_options: Mapping[str, Any] | None = None,
                 warm_duals: bool | None = None, time_budget: float | None = None,
                 solver: str | None = None,
                 sqp_options: Mapping[str, Any] | None = None) -> None:
        if formulation not in ("single-shooting", "multiple-shooting"):
            raise ValueError(f"unknown formulation {formulation!r}")
        if solver is None:
            solver = "sqp" if formulation == "single-shooting" and not ipopt_options else "ipopt"
        if solver not in ("ipopt", "sqp") or (solver == "sqp"
                                               and formulation != "single-shooting"):
            raise ValueError(f"unknown solver {solver!r} for formulation {formulation!r}")
        self.solver = solver
        self.sqp_options = {**SQP_OPTIONS, **(sqp_options or {})}
        self._eigen_clip: float | None = None
        self.params = {k: np.asarray(v, dtype=float) for k, v in params.items()}
        self.n, self.m, self.p = gru.dimensions(self.params)
        self.N = int(N)
        self.Q = np.asarray(Q, dtype=float)
        self.R = np.asarray(R, dtype=float)
        self.L = np.atleast_2d(np.asarray(L, dtype=float))
        self.q = self.L.shape[0]
        self.h = np.asarray(h, dtype=float).reshape(self.q)
        self.w_L = np.asarray(w_L, dtype=float).reshape(self.q)
        self.a = np.asarray(a, dtype=float)
        self.b = np.asarray(b, dtype=float)
        if self.a.shape[0] < self.N or self.b.shape[0] < self.N:
            raise ValueError(f"a and b need at least N = {self.N} rows (i = 0 … N−1)")
        self.a = self.a[: self.N].reshape(self.N, self.q)
        self.b = self.b[: self.N].reshape(self.N, self.q)
        self.s = float(s)
        self.formulation = formulation
        self.time_budget = None if time_budget is None else float(time_budget)
        self._deadline = float("inf")
        self.warm_duals = (formulation == "single-shooting") if warm_duals is None else warm_duals
        base = dict(FAST_IPOPT_OPTIONS) if formulation == "single-shooting" else {
            "print_level": 0, "sb": "yes"}
        base.update(ipopt_options or {})
        self.ipopt_options = base
        self.LUo = self.L @ self.params["U_o"]
        self.Lbo = self.L @ self.params["b_o"]
        self._pair_rows()
        self._solver = None
        self._buffer: tuple | None = None

    # -- construction ------------------------------------------------------------------
    def _pair_rows(self) -> None:
        """Merge opposite rows of ``L`` (``L_k = −L_j``, a box) into two-sided constraints.

        The single-shooting NLP then has one row ``D U_o x_i`` with bounds
        ``[−rhs_k, rhs_j]`` per pair instead of two: a smaller KKT system for IPOPT. ``up[r]``
        / ``lo[r]`` are the ``L`` rows giving the upper / lower bound of reduced row ``r``
        (−1: none).
        """
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
        self._up = np.array(up)
        self._lo = np.array(lo)

    def _layout(self) -> None:
        n, m, N = self.n, self.m, self.N
        if self.formulation == "single-shooting":
            self.nw = N * m + 1
            self.iu = np.arange(N * m).reshape(N, m)
            self.it = N * m
            self.ix = None
        else:
            # stage order x0, u0, x1, u1, …, x_N, t (what structure-exploiting solvers want)
            idx = 0
            ix, iu = [], []
            for _ in range(N):
                ix.append(np.arange(idx, idx + n))
                idx += n
                iu.append(np.arange(idx, idx + m))
                idx += m
            ix.append(np.arange(idx, idx + n))
            idx += n
            self.ix = np.array(ix)
            self.iu = np.array(iu)
            self.it = idx
            self.nw = idx + 1

    def setup(self) -> FHOCP:
        """Build (and optionally compile) the solver. Returns ``self``."""
        self._layout()
        if self.formulation == "single-shooting":
            nlp, opts = self._single_shooting()
        else:
            nlp, opts = self._multiple_shooting()
        self._bounds()
        if self.solver == "sqp":
            opts = {k: v for k, v in opts.items()
                    if k not in ("ipopt", "grad_f", "jac_g", "hess_lag")}
            opts.update(self._sqp_callbacks)
            sqp = dict(self.sqp_options)
            clip = sqp.pop("hessian_eigen_clip", None)
            self._eigen_clip = None if clip is None else float(clip)
            opts.update(sqp)
            with _quiet_stdout():  # qpOASES prints its licence banner on construction
                self._solver = ca.nlpsol("fhocp", "sqpmethod", nlp, opts)
        else:
            self._solver = ca.nlpsol("fhocp", "ipopt", nlp, opts)
        self._buffer = None
        if self.solver == "sqp":
            with _quiet_stdout():  # … or when its memory is allocated
                self._call_solver_setup()
        self._warm: dict[str, np.ndarray] | None = None
        return self

    def _residual_weights(self) -> tuple[np.ndarray, np.ndarray]:
        return np.linalg.cholesky(self.Q).T, np.linalg.cholesky(self.R).T

    def _multiple_shooting(self) -> tuple[dict, dict]:
        """The plain formulation: states as variables, exact Hessian (do-mpc style)."""
        n, m, N = self.n, self.m, self.N
        ops = gru.casadi_ops()
        P = {k: ca.DM(v) for k, v in self.params.items()}
        w = ca.SX.sym("w", self.nw)
        par = ca.SX.sym("p", 2 * n + m)  # x̂, x̄, ū
        x_hat, x_bar, u_bar = par[:n], par[n:2 * n], par[2 * n:]
        Qh, Rh = self._residual_weights()
        t = w[self.it]
        us = [w[self.iu[i].tolist()] for i in range(N)]
        xs = [w[self.ix[i].tolist()] for i in range(N + 1)]
        g: list[Any] = [xs[0] - x_hat]
        g += [gru.step(P, xs[i], us[i], ops) - xs[i + 1] for i in range(N)]
        g += [ca.mtimes(ca.DM(self.LUo), xs[i]) for i in range(N)]
        g += [xs[N] - x_bar - t, xs[N] - x_bar + t]
        res = [ca.mtimes(ca.DM(Qh), xs[i] - x_bar) for i in range(N)]
        res += [ca.mtimes(ca.DM(Rh), us[i] - u_bar) for i in range(N)]
        res.append(np.sqrt(self.s) * t)
        r = ca.vertcat(*res)
        gv = ca.vertcat(*g)
        self.ng = gv.shape[0]
        self._xtraj = ca.Function("xtraj", [w, par], [ca.horzcat(*xs).T])
        nlp = {"x": w, "p": par, "f": ca.dot(r, r), "g": gv}
        return nlp, {"ipopt": dict(self.ipopt_options), "print_time": False}

    def _single_shooting(self) -> tuple[dict, dict]:
        """Inputs and ``t`` as variables; states, sensitivities and the exact Hessian of the
        Lagrangian from :class:`controllers.shooting.GRUShooting` (numpy, BLAS), handed to
        IPOPT as casadi callbacks. The rollout at one point is cached and shared by the
        cost, constraint, gradient, Jacobian and Hessian evaluations at that point."""
        from controllers.shooting import GRUShooting

        n, m, N, q = self.n, self.m, self.N, self.qr
        nw, npar = self.nw, 2 * n + m
        self._shoot = GRUShooting(self.params, N)
        self.ng = (N - 1) * q + 2 * n
        self._cache: dict[str, Any] = {"key": None}
        iu = self.iu.ravel()
        stages = np.arange(N)
        triu_r, triu_c = np.triu_indices(nw)
        order = np.lexsort((triu_r, triu_c))  # casadi stores nonzeros column by column
        triu_r, triu_c = triu_r[order], triu_c[order]
        sp_triu = ca.Sparsity.upper(nw)

        def roll(wv: np.ndarray, pv: np.ndarray, deriv: bool) -> Any:
            key = (wv.tobytes(), pv.tobytes())
            c = self._cache
            if c["key"] == key and (c["deriv"] or not deriv):
                return c["ro"]
            ro = self._shoot.rollout(pv[:n], wv[iu].reshape(N, m), derivatives=deriv)
            c.update(key=key, deriv=deriv, ro=ro)
            return ro

        def split(pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return pv[n:2 * n], pv[2 * n:]

        def f_of(wv: np.ndarray, pv: np.ndarray, ro: Any) -> float:
            x_bar, u_bar = split(pv)
            return self.cost(ro.x, ro.u, x_bar, u_bar, float(wv[self.it]))

        def g_of(pv: np.ndarray, wv: np.ndarray, ro: Any) -> np.ndarray:
            x_bar, _ = split(pv)
            t = wv[self.it]
            dN = ro.x[N] - x_bar
            return np.concatenate([(ro.x[1:N] @ self.DUo.T).ravel(), dN - t, dN + t])

        # f and g are evaluated at trial points that IPOPT mostly accepts; computing the
        # derivatives there too saves a second rollout when grad/jac/hess follow.
        def f_fn(wv, pv):
            return [f_of(wv, pv, roll(wv, pv, True))]

        def g_fn(wv, pv):
            return [g_of(pv, wv, roll(wv, pv, True))]

        def grad_fn(wv, pv):
            ro = roll(wv, pv, True)
            x_bar, u_bar = split(pv)
            grad = np.zeros(nw)
            dx = (ro.x[1:N] - x_bar) @ (2 * self.Q)
            grad[iu] = dx.ravel() @ ro.S[1:N].reshape((N - 1) * n, N * m) + (
                (ro.u - u_bar) @ (2 * self.R)).ravel()
            grad[self.it] = 2 * self.s * wv[self.it]
            return [f_of(wv, pv, ro), grad]

        def jac_fn(wv, pv):
            ro = roll(wv, pv, True)
            J = np.zeros((self.ng, nw))
            J[: (N - 1) * q, iu] = np.matmul(self.DUo[None], ro.S[1:N]).reshape(
                (N - 1) * q, N * m)
            J[(N - 1) * q:(N - 1) * q + n, iu] = ro.S[N]
            J[(N - 1) * q + n:, iu] = ro.S[N]
            J[(N - 1) * q:(N - 1) * q + n, self.it] = -1.0
            J[(N - 1) * q + n:, self.it] = 1.0
            return [g_of(pv, wv, ro), J]

        def hess_fn(wv, pv, lf, lg):
            H = hess_full(wv, pv, lf, lg)
            return [H[triu_r, triu_c]]

        def hess_full(wv, pv, lf, lg):
            ro = roll(wv, pv, True)
            x_bar, _ = split(pv)
            lf = float(lf[0])
            lam_out = lg[: (N - 1) * q].reshape(N - 1, q)
            lam_term = lg[(N - 1) * q:(N - 1) * q + n] + lg[(N - 1) * q + n:]
            # adjoints μ_i of the state terms, i = 1 … N
            c = np.zeros((N + 1, n))
            c[1:N] = 2 * lf * (ro.x[1:N] - x_bar) @ self.Q + lam_out @ self.DUo
            c[N] = lam_term
            mu = np.zeros((N + 1, n))
            mu[N] = c[N]
            for i in range(N - 1, 0, -1):
                mu[i] = c[i] + ro.A[i].T @ mu[i + 1]
            W = self._shoot.stage_hessians(ro, mu[1:])
            W[1:, :n, :n] += 2 * lf * self.Q
            S = ro.S[:N]
            H = np.zeros((nw, nw))
            ST = np.transpose(S, (0, 2, 1))
            SW = np.matmul(ST, W[:, :n, :n])
            Huu = SW.reshape(N * N * m, n).reshape(N, N * m, n)
            Huu = np.matmul(Huu.transpose(1, 0, 2).reshape(N * m, N * n),
                            S.reshape(N * n, N * m))
            C = np.matmul(ST, W[:, :n, n:])  # (N, Nm, m): ∂²/∂u ∂u_i of the x–u terms
            Ct = C.transpose(1, 0, 2).reshape(N * m, N * m)   # column block i = C[i]
            Huu += Ct + Ct.T
            Hv = Huu.reshape(N, m, N, m)
            Hv[stages, :, stages, :] += W[:, n:, n:] + 2 * lf * self.R
            H[np.ix_(iu, iu)] = Huu
            H[self.it, self.it] = 2 * lf * self.s
            return H

        sp = ca.Sparsity.dense
        self._callbacks = [
            _NumpyFunction("fhocp_f", f_fn, [sp(nw), sp(npar)], [sp(1)], ["x", "p"], ["f"]),
            _NumpyFunction("fhocp_g", g_fn, [sp(nw), sp(npar)], [sp(self.ng)], ["x", "p"],
                           ["g"]),
            _NumpyFunction("nlp_grad_f", grad_fn, [sp(nw), sp(npar)], [sp(1), sp(nw)],
                           ["x", "p"], ["f", "grad_f_x"]),
            _NumpyFunction("nlp_jac_g", jac_fn, [sp(nw), sp(npar)],
                           [sp(self.ng), sp(self.ng, nw)], ["x", "p"], ["g", "jac_g_x"]),
            _NumpyFunction("nlp_hess_l", hess_fn, [sp(nw), sp(npar), sp(1), sp(self.ng)],
                           [sp_triu], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
        ]
        fcb, gcb, gradcb, jaccb, hesscb = self._callbacks

        def jac_fg_fn(wv, pv):
            f, grad = grad_fn(wv, pv)
            g, J = jac_fn(wv, pv)
            return [f, grad, g, J]

        def hess_full_fn(wv, pv, lf, lg):
            H = hess_full(wv, pv, lf, lg)
            if self._eigen_clip is not None:
                # convexified for the QP: eigenvalues below the margin clipped (LAPACK eigh,
                # ~40 µs for 31×31, instead of sqpmethod's Jacobi sweeps)
                ev, V = np.linalg.eigh(H)
                if ev[0] < self._eigen_clip:
                    H = (V * np.maximum(ev, self._eigen_clip)) @ V.T
            return [H]

        # sqpmethod (``solver="sqp"``) takes f, ∇f, g, ∂g/∂w in one function and the full
        # (symmetric) Hessian of the Lagrangian
        self._callbacks_sqp = [
            _NumpyFunction("nlp_jac_fg", jac_fg_fn, [sp(nw), sp(npar)],
                           [sp(1), sp(nw), sp(self.ng), sp(self.ng, nw)], ["x", "p"],
                           ["f", "grad_f_x", "g", "jac_g_x"]),
            _NumpyFunction("nlp_hess_l", hess_full_fn, [sp(nw), sp(npar), sp(1), sp(self.ng)],
                           [sp(nw, nw)], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"]),
        ]
        self._sqp_callbacks = {"jac_fg": self._callbacks_sqp[0],
                               "hess_lag": self._callbacks_sqp[1]}
        w = ca.MX.sym("w", nw)
        par = ca.MX.sym("p", npar)
        def xtraj(wv: np.ndarray, pv: np.ndarray) -> np.ndarray:
            # the solver's own trajectory at its answer: usually the last point evaluated
            wv, pv = np.asarray(wv, dtype=float).ravel(), np.asarray(pv, dtype=float).ravel()
            c = self._cache
            if c["key"] == (wv.tobytes(), pv.tobytes()):
                return c["ro"].x
            return self._shoot.rollout(pv[:n], wv[iu].reshape(N, m), derivatives=False).x

        self._xtraj = xtraj
        def stop_fn(*_: np.ndarray) -> list[np.ndarray]:
            # IPOPT stops ("User_Requested_Stop") when the iteration callback returns nonzero
            return [np.array([1.0 if time.perf_counter() > self._deadline else 0.0])]

        self._callbacks.append(_NumpyFunction(
            "time_budget", stop_fn, [sp(nw), sp(1), sp(self.ng), sp(nw), sp(self.ng),
                                     sp(npar)], [sp(1)],
            ["x", "f", "g", "lam_x", "lam_g", "lam_p"], ["ret"]))
        opts: dict[str, Any] = {"ipopt": dict(self.ipopt_options), "print_time": False,
                                "grad_f": gradcb, "jac_g": jaccb, "hess_lag": hesscb,
                                "no_nlp_grad": True, "calc_lam_p": False,
                                "calc_lam_x": False, "calc_f": False, "calc_g": False}
        if self.time_budget is not None:
            opts["iteration_callback"] = self._callbacks[-1]
        return {"x": w, "p": par, "f": fcb(w, par), "g": gcb(w, par)}, opts

    def _bounds(self) -> None:
        lbx = np.full(self.nw, -np.inf)
        ubx = np.full(self.nw, np.inf)
        lbx[self.iu.ravel()] = -1.0
        ubx[self.iu.ravel()] = 1.0
        lbx[self.it] = 0.0
        self._lbx, self._ubx = lbx, ubx

    # -- solving -----------------------------------------------------------------------
    def tightened_bounds(self, e_o: float) -> np.ndarray:
        """Right-hand sides ``h − a_i ê_o − b_i − w_L − L b_o`` for ``i = 0 … N−1`` (N×q)."""
        return self.h - self.a * e_o - self.b - self.w_L - self.Lbo

    def rollout(self, x_hat: np.ndarray, u_seq: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` of ``eq:gru`` from ``x̂`` under ``u_seq`` (N, m)."""
        if self._solver is None:
            self.setup()
        if self.formulation == "single-shooting":
            return self._shoot.rollout(x_hat, u_seq, derivatives=False).x
        return gru.simulate(self.params, x_hat, u_seq)[0]

    def check_x0(self, x_hat: np.ndarray, e_o: float) -> float:
        """Violation of the ``i = 0`` constraint at ``x̂`` (≤ 0 when satisfied)."""
        return float(np.max(self.LUo @ x_hat - self.tightened_bounds(e_o)[0]))

    def candidate(self, x_hat: np.ndarray, u_seq: np.ndarray, x_bar: np.ndarray,
                  u_bar: np.ndarray, e_o: float, alpha: float) -> FHOCPResult:
        """Evaluate a given input sequence (cost, trajectory, residuals) without solving."""
        u_seq = np.clip(np.asarray(u_seq, dtype=float), -1.0, 1.0)
        x, _ = gru.simulate(self.params, np.asarray(x_hat, dtype=float), u_seq)
        tN = float(np.max(np.abs(x[-1] - x_bar)))
        res = FHOCPResult(u=u_seq, x=x, cost=self.cost(x, u_seq, x_bar, u_bar, tN),
                          status="candidate", success=False, t=tN)
        self._residuals(res, x, e_o, x_bar, alpha)
        return res

    def cost(self, x: np.ndarray, u: np.ndarray, x_bar: np.ndarray, u_bar: np.ndarray,
             t: float | None = None) -> float:
        """Cost ``eq:optimization-cost`` (``t`` defaults to ``‖x_N − x̄‖∞``)."""
        dx = x[: self.N] - x_bar
        du = u - u_bar
        tN = float(np.max(np.abs(x[self.N] - x_bar))) if t is None else t
        return float(np.vdot(dx @ self.Q, dx) + np.vdot(du @ self.R, du) + self.s * tN ** 2)

    def _residuals(self, res: FHOCPResult, x: np.ndarray, e_o: float, x_bar: np.ndarray,
                   alpha: float) -> None:
        ub = self.tightened_bounds(e_o)
        lhs = x[: self.N] @ self.LUo.T
        viol = max(0.0, float(np.max(lhs - ub)),
                   float(np.max(np.abs(res.u))) - 1.0)
        res.constraint_violation = viol
        dN = float(np.max(np.abs(x[self.N] - x_bar)))
        res.terminal_violation = max(0.0, dN - alpha)
        act = int(np.sum(lhs[1:] - ub[1:] > -1e-6)) + int(dN - alpha > -1e-6)
        act += int(np.sum(np.abs(res.u) > 1 - 1e-6))
        res.active = act

    def _initial_guess(self, x_hat: np.ndarray, u_init: np.ndarray, t_init: float,
                       ) -> np.ndarray:
        w0 = np.zeros(self.nw)
        w0[self.iu] = u_init
        w0[self.it] = t_init
        if self.ix is not None:
            x, _ = gru.simulate(self.params, x_hat, u_init)
            w0[self.ix] = x
        return w0

    def solve(self, x_hat: np.ndarray, e_o: float, x_bar: np.ndarray, u_bar: np.ndarray,
              alpha: float, u_init: np.ndarray | None = None, warm: bool = True,
              ) -> FHOCPResult:
        """Solve ``eq:optimization`` at ``x̂`` with ``ê_o``, set-point ``(x̄, ū)``, terminal α.

        Parameters
        ----------
        u_init : (N, m) array, optional
            Initial guess of the inputs; default: the previous solution shifted by one stage
            with ``ū`` appended (and its multipliers, shifted too) when ``warm``, else ``ū``.
        """
        if self._solver is None:
            self.setup()
        x_hat = np.asarray(x_hat, dtype=float).reshape(self.n)
        x_bar = np.asarray(x_bar, dtype=float).reshape(self.n)
        u_bar = np.asarray(u_bar, dtype=float).reshape(self.m)
        t0 = time.perf_counter()
        if self.formulation == "single-shooting" and self.check_x0(x_hat, e_o) > 0:
            res = self.candidate(x_hat, np.tile(u_bar, (self.N, 1)), x_bar, u_bar, e_o, alpha)
            res.status = "infeasible_x0"
            res.solve_time = time.perf_counter() - t0
            return res
        args = self._arguments(x_hat, e_o, x_bar, u_bar, alpha, u_init, warm)
        self._deadline = t0 + (self.time_budget if self.time_budget is not None else np.inf)
        sol, stats = self._call_solver(args)
        if stats.get("return_status") == "User_Requested_Stop":
            stats = {**stats, "return_status": "time_budget_exceeded", "success": False}
        elapsed = time.perf_counter() - t0
        wopt = np.asarray(sol["x"]).ravel()
        u = np.clip(wopt[self.iu], -1.0, 1.0)  # IPOPT may overshoot a bound by ~1e-9
        xs = np.asarray(self._xtraj(wopt, args["p"]))
        x, _ = gru.simulate(self.params, x_hat, np.clip(u, -1.0, 1.0))
        t = float(wopt[self.it])
        res = FHOCPResult(u=u, x=x, cost=self.cost(x, u, x_bar, u_bar), status=str(
            stats.get("return_status", "unknown")), success=False,
            iterations=int(stats.get("iter_count", 0)), solve_time=elapsed, t=t,
            lam_x=np.asarray(sol["lam_x"]).ravel(), lam_g=np.asarray(sol["lam_g"]).ravel())
        res.defect = float(np.max(np.abs(xs - x)))
        self._residuals(res, x, e_o, x_bar, alpha)
        ok_status = bool(stats.get("success", False))
        res.feasible = bool(np.all(np.isfinite(wopt)) and res.constraint_violation <= FEAS_TOL
                            and res.terminal_violation <= FEAS_TOL
                            and res.defect <= DEFECT_TOL)
        res.success = ok_status and res.feasible
        if ok_status and res.status == "Solve_Succeeded":
            res.status = "optimal"
        elif ok_status and not res.success:
            res.status = "residual_check_failed"
        elif res.status == "Solve_Succeeded":
            # sqpmethod aborted (e.g. a failed QP) and left the previous solve's status
            res.status = "solver_aborted"
        if res.success or (np.all(np.isfinite(wopt)) and np.all(np.isfinite(res.lam_g))
                           and np.all(np.isfinite(res.lam_x))):
            # after a failure (time budget, infeasibility) the last primal-dual iterate is
            # the best start for the next step: the optimisation continues across steps
            self._warm = {"w": wopt, "lam_x": res.lam_x, "lam_g": res.lam_g}
        return res

    def _call_solver_setup(self) -> None:
        """Bind numpy arrays to the solver's zero-copy argument and result buffers."""
        fn = self._solver
        buf, trigger = fn.buffer()
        ins = {name: np.zeros(fn.sparsity_in(i).nnz()) for i, name in enumerate(fn.name_in())}
        outs = {name: np.zeros(fn.sparsity_out(i).nnz())
                for i, name in enumerate(fn.name_out())}
        for i, name in enumerate(fn.name_in()):
            buf.set_arg(i, memoryview(ins[name]))
        for i, name in enumerate(fn.name_out()):
            buf.set_res(i, memoryview(outs[name]))
        self._buffer = (buf, trigger, ins, outs)

    def _call_solver(self, args: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict]:
        """Run the solver; returns the solution arrays and the solver statistics.

        Arguments and results go through casadi's zero-copy buffers: converting numpy arrays
        to and from ``DM`` costs tens of microseconds per vector.
        """
        if self._buffer is None:
            self._call_solver_setup()
        buf, trigger, ins, outs = self._buffer
        for name, arr in ins.items():
            arr[:] = args.get(name, 0.0)
        trigger()
        try:
            stats = buf.stats()
        except RuntimeError:
            # casadi 3.8 sqpmethod: no return status after a failed line search
            stats = {"return_status": "Solver_Stats_Unavailable", "success": False}
        return {k: v.copy() for k, v in outs.items()}, stats

    def reset_warm_start(self) -> None:
        """Forget the previous solution (next solve starts cold)."""
        self._warm = None

    def _arguments(self, x_hat: np.ndarray, e_o: float, x_bar: np.ndarray, u_bar: np.ndarray,
                   alpha: float, u_init: np.ndarray | None, warm: bool) -> dict[str, Any]:
        N, q, n = self.N, self.q, self.n
        ub = self.tightened_bounds(e_o)
        lbg = np.full(self.ng, -np.inf)
        ubg = np.full(self.ng, np.inf)
        if self.formulation == "single-shooting":
            qr, up, lo = self.qr, self._up, self._lo
            ubg[: (N - 1) * qr] = ub[1:, up].ravel()
            lower = np.where(lo >= 0, -ub[1:, np.maximum(lo, 0)], -np.inf)
            lbg[: (N - 1) * qr] = lower.ravel()
            off = (N - 1) * qr
        else:
            neq = (N + 1) * n
            lbg[:neq] = 0.0
            ubg[:neq] = 0.0
            ubg[neq: neq + N * q] = ub.ravel()
            off = neq + N * q
        ubg[off: off + n] = 0.0
        lbg[off + n: off + 2 * n] = 0.0
        ubx = self._ubx.copy()
        ubx[self.it] = alpha
        args: dict[str, Any] = {"p": np.concatenate([x_hat, x_bar, u_bar]), "lbx": self._lbx,
                                "ubx": ubx, "lbg": lbg, "ubg": ubg}
        prev = self._warm if warm else None
        if u_init is None:
            if prev is not None:
                u_prev = prev["w"][self.iu]
                u_init = np.vstack([u_prev[1:], u_bar])
            else:
                u_init = np.tile(u_bar, (N, 1))
        u_init = np.clip(u_init, -1.0, 1.0)
        if self.formulation == "single-shooting":
            x = self._shoot.rollout(x_hat, u_init, derivatives=False).x
        else:
            x, _ = gru.simulate(self.params, x_hat, u_init)
        t_init = min(max(float(np.max(np.abs(x[-1] - x_bar))), 1e-6), max(alpha, 0.0))
        args["x0"] = self._initial_guess(x_hat, u_init, t_init)
        if prev is not None and self.warm_duals:
            args["lam_x0"] = self._shift(prev["lam_x"], "x")
            args["lam_g0"] = self._shift(prev["lam_g"], "g")
        return args

    def _shift(self, lam: np.ndarray, kind: str) -> np.ndarray:
        """Shift multipliers by one stage (the last stage keeps its values)."""
        lam = lam.copy()
        N, q = self.N, self.qr
        if kind == "x":
            lu = lam[self.iu]
            lam[self.iu] = np.vstack([lu[1:], lu[-1:]])
            if self.ix is not None:
                lx = lam[self.ix]
                lam[self.ix] = np.vstack([lx[1:], lx[-1:]])
        elif self.formulation == "single-shooting":
            blk = lam[: (N - 1) * q].reshape(N - 1, q)
            lam[: (N - 1) * q] = np.vstack([blk[1:], blk[-1:]]).ravel()
        return lam


#: Integer codes of the step status recorded in the diagnostics.
STATUS_CODES = {"optimal": 0, "infeasible_x0": 1, "Infeasible_Problem_Detected": 2,
                "Maximum_Iterations_Exceeded": 3, "Maximum_WallTime_Exceeded": 3,
                "Maximum_CpuTime_Exceeded": 3, "time_budget_exceeded": 3,
                "residual_check_failed": 4}
OTHER_STATUS = 5


@dataclass
class StepRecord:
    """What happened at one controller step (normalised units).

    Attributes
    ----------
    u : (m,) array
        Applied input.
    result : FHOCPResult
        The solve (its ``status`` says why a fallback happened).
    fallback : bool
        The shifted previous solution (``ū`` appended) was applied instead of the optimum.
    candidate_feasible : bool
        For a fallback: whether that shifted sequence satisfies the FHOCP constraints at
        ``x̂_k`` (Theorem 3 says it does when its hypotheses hold).
    """

    u: np.ndarray
    result: FHOCPResult
    fallback: bool
    candidate_feasible: bool = True
    suboptimal: bool = False
    x_hat: np.ndarray | None = None
    e_o: float = 0.0


class RobustMPC:
    """The MPC law ``eq:mpc`` with the fallback of the proof of ``th:feasibility-stability``.

    At each step the FHOCP is solved from the candidate of the proof (the previous sequence
    shifted by one stage with ``ū`` appended). When the solve fails (solver failure,
    infeasibility, iteration or time limit, or a failed residual check) that candidate is
    applied instead, and the next step shifts it again. Before any successful solve the
    candidate is ``ū`` repeated.

    Suboptimal MPC (``accept_suboptimal``, default on): when the solve stops at the
    iteration cap with an iterate that passes every residual check (feasible) and costs no
    more than the candidate, that iterate is applied instead of the candidate (Scokaert,
    Mayne & Rawlings 1999: feasibility and the candidate's cost decrease are what the proof of
    ``th:feasibility-stability`` uses). Counted as ``suboptimal_steps``, not as fallbacks.

    Parameters
    ----------
    fhocp : FHOCP
        The problem (set up on first use).
    accept_suboptimal : bool
        Apply feasible capped iterates (see above); ``False``: only converged solves.
    """

    def __init__(self, fhocp: FHOCP, accept_suboptimal: bool = True) -> None:
        self.fhocp = fhocp
        self.accept_suboptimal = bool(accept_suboptimal)
        self.x_bar: np.ndarray | None = None
        self.u_bar: np.ndarray | None = None
        self.alpha: float = float("nan")
        self.plan: np.ndarray | None = None
        self.records: list[StepRecord] = []

    def set_reference(self, x_bar: np.ndarray, u_bar: np.ndarray, alpha: float) -> None:
        """Set-point data ``(x̄, ū, α)`` (``eq:def-alpha``); call again when ``ȳ`` changes."""
        self.x_bar = np.asarray(x_bar, dtype=float)
        self.u_bar = np.asarray(u_bar, dtype=float)
        self.alpha = float(alpha)

    def candidate(self) -> np.ndarray:
        """The shifted previous sequence with ``ū`` appended (``ū`` repeated at first)."""
        assert self.u_bar is not None
        if self.plan is None:
            return np.tile(self.u_bar, (self.fhocp.N, 1))
        return np.vstack([self.plan[1:], self.u_bar])

    def make_step(self, x_hat: np.ndarray, e_o: float,
                  candidate: np.ndarray | None = None) -> StepRecord:
        """Compute ``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``), with the fallback.

        ``candidate`` (N, m), optional: a sequence known to be feasible (the reference
        governor's, :mod:`controllers.governor`); it is the initial guess of the solve and
        the fallback, in place of the shifted previous plan.
        """
        if self.x_bar is None or self.u_bar is None:
            raise RuntimeError("set_reference() must be called before make_step()")
        cand = self.candidate() if candidate is None else np.asarray(candidate, dtype=float)
        # the FHOCP warm-starts from its own last iterate shifted by one stage: the candidate
        # itself after a success, the partially converged iterate after a failure
        t0 = time.perf_counter()
        try:
            res = self.fhocp.solve(x_hat, e_o, self.x_bar, self.u_bar, self.alpha,
                                   u_init=candidate)
        except Exception as exc:
            res = self.fhocp.candidate(x_hat, cand, self.x_bar, self.u_bar, e_o, self.alpha)
            res.status = f"solver_error: {type(exc).__name__}: {exc}"[:200]
            res.solve_time = time.perf_counter() - t0
        if res.success:
            self.plan = res.u.copy()
            rec = StepRecord(u=res.u[0].copy(), result=res, fallback=False)
            rec.x_hat, rec.e_o = np.array(x_hat, dtype=float), float(e_o)
            self.records.append(rec)
            return rec
        chk = self.fhocp.candidate(x_hat, cand, self.x_bar, self.u_bar, e_o, self.alpha)
        feasible = chk.constraint_violation <= FEAS_TOL and chk.terminal_violation <= FEAS_TOL
        if self.accept_suboptimal and res.feasible and (
                not feasible or res.cost <= chk.cost):
            # suboptimal MPC: a feasible iterate no costlier than the candidate keeps the
            # proof's arguments (feasibility, and the cost decrease the candidate gives)
            self.plan = res.u.copy()
            rec = StepRecord(u=res.u[0].copy(), result=res, fallback=False, suboptimal=True,
                             x_hat=np.array(x_hat, dtype=float), e_o=float(e_o))
        else:
            self.plan = cand
            rec = StepRecord(u=np.clip(cand[0], -1.0, 1.0), result=res, fallback=True,
                             candidate_feasible=bool(feasible),
                             x_hat=np.array(x_hat, dtype=float), e_o=float(e_o))
        self.records.append(rec)
        return rec

    def summary(self) -> dict[str, Any]:
        """Solver statistics over the steps so far."""
        return solver_summary(self.records)


def solver_summary(records: list[StepRecord]) -> dict[str, Any]:
    """Median / p99 / max solve time [ms], iterations, failures by status, fallbacks."""
    if not records:
        return {"steps": 0}
    t = np.array([r.result.solve_time for r in records]) * 1e3
    it = np.array([r.result.iterations for r in records])
    statuses: dict[str, int] = {}
    for r in records:
        if not r.result.success:
            key = r.result.status.split(":")[0]
            statuses[key] = statuses.get(key, 0) + 1
    return {
        "steps": len(records),
        "solve_ms_median": float(np.median(t)),
        "solve_ms_p99": float(np.percentile(t, 99)),
        "solve_ms_max": float(np.max(t)),
        "iterations_median": float(np.median(it)),
        "iterations_max": int(np.max(it)),
        "failures": int(sum(statuses.values())),
        "failures_by_status": statuses,
        "fallbacks": int(sum(r.fallback for r in records)),
        "suboptimal_steps": int(sum(r.suboptimal for r in records)),
        "fallback_candidates_infeasible": int(sum(r.fallback and not r.candidate_feasible
                                                  for r in records)),
    }
