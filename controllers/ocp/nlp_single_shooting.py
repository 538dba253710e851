"""The FHOCP ``eq:optimization`` as a single-shooting NLP with exact numpy derivatives.

Decision variables ``w = (u_0 … u_{N−1}, t)`` (``N m + 1``: 31 for N = 15, m = 2); the
states, their sensitivities and the exact Hessian of the Lagrangian come from
:class:`controllers.ocp.shooting.GRUShooting` (dense numpy products, checked against casadi AD of
:func:`controllers.gru.step`) and reach the solver through zero-copy casadi callbacks
(:class:`controllers.ocp.casadi_callbacks.NumpyCallback`). Constraints, in this order:

* ``D U_o x_i`` for ``i = 1 … N−1``, one row per pair of opposite rows of ``L`` (a box),
  bounded by the tightened bounds (``eq:optimization-constraint``; ``i = 0`` involves only
  ``x̂`` and is checked before the solve);
* ``x_N − x̄ − t ≤ 0`` and ``x_N − x̄ + t ≥ 0``: the epigraph of ``‖x_N − x̄‖∞`` (terminal cost
  ``s t²``, terminal set ``0 ≤ t ≤ α``).

Softened (``FHOCP(soft=True)``, :mod:`controllers.ocp.soft`): ``w`` ends with the slacks
``ε``, the rows are not paired, and the slacks' terms are added to what the law's methods
compute over the rest of ``w`` (:meth:`SingleShootingNLP.f`, :meth:`~SingleShootingNLP.g`,
:meth:`~SingleShootingNLP.gradient`, :meth:`~SingleShootingNLP.jacobian`,
:meth:`~SingleShootingNLP.hessian`).

Parameters ``p = (x̂, x̄, ū)``, and ``u_{−1}`` after them when the cost has the input-rate
term (:mod:`controllers.ocp.input_rate`: its gradient is added to ∇f, its constant Hessian to the
input block).

The rollout at one point is cached and shared by the cost, constraint, gradient, Jacobian
and Hessian evaluations at that point (one rollout serves a whole SQP iteration).

With a compiled kernel (:mod:`controllers.kernel.compiled_kernel`: the same mathematics in C,
checked against these numpy functions by :meth:`SingleShootingNLP.self_test`), the SQP's
functions are the kernel's casadi ``external`` functions instead: no Python runs inside the
solver.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from controllers.ocp.casadi_callbacks import NumpyCallback
from controllers.ocp.input_rate import du_gradient, du_hessian

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["SingleShootingNLP", "clip_eigenvalues"]


def clip_eigenvalues(H: np.ndarray, margin: float) -> np.ndarray:
    """The symmetric ``H`` with its eigenvalues below ``margin`` raised to it (LAPACK
    ``eigh``; ``H`` itself when none is): the SQP's convex QP Hessian, the reference of the
    compiled kernel's clipping."""
    ev, V = np.linalg.eigh(H)
    return H if ev[0] >= margin else (V * np.maximum(ev, margin)) @ V.T


class SingleShootingNLP:
    """The numpy side of the single-shooting FHOCP: function and derivative evaluations.

    Parameters
    ----------
    fhocp : FHOCP
        The problem (dimensions, weights, constraint rows, layout of ``w``).
    kernel : kernel_lib.Workspace, optional
        A workspace of this problem's compiled kernel: :meth:`sqp_problem` (the library's
        external functions) and :meth:`trajectory` use it.

    Attributes
    ----------
    ng : int
        Number of constraints.
    eigen_clip : float or None
        Eigenvalues of the Hessian handed to an SQP's QP are clipped at this margin
        (:meth:`hessian_convex`); ``None``: the exact Hessian.
    deadline : float
        ``time.perf_counter()`` value past which IPOPT's iteration callback stops the solve.
    """

    def __init__(self, fhocp: FHOCP, kernel: Any = None) -> None:
        from controllers.ocp.shooting import GRUShooting

        self.p = fhocp
        self.kernel = kernel
        self.shoot = GRUShooting(fhocp.params, fhocp.N)
        self.ng = fhocp.ng
        #: the law's own rows (without the move limit's, appended by :meth:`g`)
        self.ng_law = fhocp.ng - fhocp.nmv
        self.iu = fhocp.iu.ravel()
        #: ``w``'s size without the softened rows' slacks
        self.nwh = fhocp.nw - fhocp.nsl
        self.eigen_clip: float | None = None
        self.deadline = float("inf")
        self._key: tuple[bytes, bytes] | None = None
        self._deriv = False
        self._ro: Any = None
        nw = fhocp.nw
        triu_r, triu_c = np.triu_indices(nw)
        order = np.lexsort((triu_r, triu_c))  # casadi stores nonzeros column by column
        self._triu = (triu_r[order], triu_c[order])
        self.callbacks: list[NumpyCallback] = []
        #: the input-rate term's constant Hessian (N m × N m), None without the term
        self._du_hess = du_hessian(fhocp.N, fhocp.du_weight) if fhocp.has_du else None

    @property
    def slacks(self) -> Any:
        """The FHOCP's slacks as the solve in progress has them (``None``: a hard FHOCP;
        :mod:`controllers.ocp.soft`)."""
        return self.p.slacks

    def forget(self) -> None:
        """Drop what was computed at the current biases (moved in place by
        :class:`controllers.disturbances.BiasShift`)."""
        self._key = None
        self.shoot.refresh()

    def weights_changed(self) -> None:
        """The problem's cost weights changed in place (:meth:`FHOCP.set_weight`): the
        input-rate term's constant Hessian again."""
        fh = self.p
        self._du_hess = du_hessian(fh.N, fh.du_weight) if fh.has_du else None

    # -- one point ----------------------------------------------------------------------
    def rollout(self, wv: np.ndarray, pv: np.ndarray, deriv: bool) -> Any:
        """States (and with ``deriv`` sensitivities) at ``(w, p)``, cached per point."""
        key = (wv.tobytes(), pv.tobytes())
        if self._key == key and (self._deriv or not deriv):
            return self._ro
        p = self.p
        ro = self.shoot.rollout(pv[:p.n], wv[self.iu].reshape(p.N, p.m), derivatives=deriv)
        self._key, self._deriv, self._ro = key, deriv, ro
        return ro

    def _reference(self, pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, m = self.p.n, self.p.m
        return pv[n:2 * n], pv[2 * n:2 * n + m]

    def _u_prev(self, pv: np.ndarray) -> np.ndarray | None:
        """``u_{−1}`` from ``p`` (``None`` without an input-rate term)."""
        p = self.p
        return pv[2 * p.n + p.m:] if p.has_du else None

    def objective(self, wv: np.ndarray, pv: np.ndarray, ro: Any) -> float:
        """``eq:optimization-cost`` at the rolled-out point."""
        x_bar, u_bar = self._reference(pv)
        return self.p.reference.cost(ro.x, ro.u, x_bar, u_bar, float(wv[self.p.it]),
                               self._u_prev(pv))

    def constraints(self, wv: np.ndarray, pv: np.ndarray, ro: Any) -> np.ndarray:
        """The constraint vector (see the module docstring)."""
        p = self.p
        x_bar, _ = self._reference(pv)
        t = wv[p.it]
        dN = ro.x[p.N] - x_bar
        return np.concatenate([(ro.x[1:p.N] @ p.DUo.T).ravel(), dN - t, dN + t])

    # f and g are evaluated at trial points that the solver mostly accepts; computing the
    # derivatives there too saves a second rollout when ∇f, ∂g/∂w and the Hessian follow
    def f(self, wv: np.ndarray, pv: np.ndarray) -> list:
        f = self.objective(wv, pv, self.rollout(wv, pv, True))
        return [f if self.slacks is None else f + self.slacks.penalty(wv[self.slacks.idx])]

    def g(self, wv: np.ndarray, pv: np.ndarray) -> list:
        g = self.constraints(wv, pv, self.rollout(wv, pv, True))
        g = g if self.slacks is None else self.slacks.soften(g, wv[self.slacks.idx])
        return [self._with_moves(g, wv, pv)]

    def _with_moves(self, g: np.ndarray, wv: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """``g`` with the move limit's rows after it (``eq:move-constraint``), when the
        FHOCP has them."""
        move = self.p.move
        return g if move is None else np.concatenate([g, move.rows(wv, pv)])

    def gradient(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[f, ∇f]`` (the law's :meth:`_gradient` with the slacks' terms)."""
        f, grad = self._gradient(wv, pv)
        sl = self.slacks
        if sl is None:
            return [f, grad]
        return [f + sl.penalty(wv[sl.idx]), sl.embed(grad, self.p.nw, wv)]

    def jacobian(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[g, ∂g/∂w]`` (the law's :meth:`_jacobian` with the slacks' terms)."""
        g, J = self._jacobian(wv, pv)
        sl = self.slacks
        if sl is not None:
            Js = np.zeros((J.shape[0], self.p.nw))
            Js[:, :self.nwh] = J
            sl.jacobian_columns(Js)
            g, J = sl.soften(g, wv[sl.idx]), Js
        move = self.p.move
        if move is None:
            return [g, J]
        return [self._with_moves(g, wv, pv), np.vstack([J, move.jacobian])]

    def hessian(self, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                lg: np.ndarray) -> np.ndarray:
        """The exact Hessian of the Lagrangian ``λ_f f + λ_g·g`` (dense, symmetric; the law's
        :meth:`_hessian` with the slacks' diagonal)."""
        H = self._hessian(wv, pv, lf, lg)
        if self.slacks is None:
            return H
        return self.slacks.embed(H, self.p.nw, wv, float(lf[0]))

    def stage_gradient(self, ro: Any, x_ref: np.ndarray, u_ref: np.ndarray,
                       pv: np.ndarray) -> np.ndarray:
        """∇ of the stage costs ``Σ ‖x_i − x_ref‖²_Q + ‖u_i − u_ref‖²_R`` (and the input-rate
        term) over the inputs ``u_0 … u_{N−1}`` of rollout ``ro``, the reference held fixed
        (N m,)."""
        p = self.p
        N, n, m = p.N, p.n, p.m
        dx = (ro.x[1:N] - x_ref) @ (2 * p.Q)
        g = dx.ravel() @ ro.S[1:N].reshape((N - 1) * n, N * m) + (
            (ro.u - u_ref) @ (2 * p.R)).ravel()
        if p.has_du:
            g += du_gradient(ro.u, self._u_prev(pv), p.du_weight).ravel()
        return g

    def _gradient(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[f, ∇f]`` of the hard problem (``w`` without the slacks)."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        grad = np.zeros(self.nwh)
        grad[self.iu] = self.stage_gradient(ro, *self._reference(pv), pv)
        grad[p.it] = 2 * p.s * wv[p.it]
        return [self.objective(wv, pv, ro), grad]

    def _jacobian(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[g, ∂g/∂w]`` of the hard problem (``w`` without the slacks)."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        N, n, q, iu = p.N, p.n, p.qr, self.iu
        J = np.zeros((self.ng_law, self.nwh))
        J[: (N - 1) * q, iu] = np.matmul(p.DUo[None], ro.S[1:N]).reshape((N - 1) * q, N * p.m)
        J[(N - 1) * q:(N - 1) * q + n, iu] = ro.S[N]
        J[(N - 1) * q + n:, iu] = ro.S[N]
        J[(N - 1) * q:(N - 1) * q + n, p.it] = -1.0
        J[(N - 1) * q + n:, p.it] = 1.0
        return [self.constraints(wv, pv, ro), J]

    def jac_fg(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[f, ∇f, g, ∂g/∂w]`` in one call (what ``sqpmethod`` asks for)."""
        f, grad = self.gradient(wv, pv)
        g, J = self.jacobian(wv, pv)
        return [f, grad, g, J]

    def _hessian(self, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                 lg: np.ndarray) -> np.ndarray:
        """The Hessian of the hard problem's Lagrangian (``w`` without the slacks)."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        x_bar, _ = self._reference(pv)
        lf0 = float(lf[0])
        H = np.zeros((self.nwh, self.nwh))
        H[np.ix_(self.iu, self.iu)] = self.input_hessian(ro, x_bar, lf0, lg)
        H[p.it, p.it] = 2 * lf0 * p.s
        return H

    def input_hessian(self, ro: Any, x_ref: np.ndarray, lf: float, lg: np.ndarray
                      ) -> np.ndarray:
        """The block of the inputs ``u_0 … u_{N−1}`` (N m × N m) of the Hessian of the
        Lagrangian at rollout ``ro``, the reference ``x_ref`` held fixed; ``lg``: the
        multipliers of the output rows and the terminal rows (its first ``(N−1) q + 2 n``
        entries are read)."""
        p = self.p
        N, n, m, q = p.N, p.n, p.m, p.qr
        lam_out = lg[: (N - 1) * q].reshape(N - 1, q)
        lam_term = lg[(N - 1) * q:(N - 1) * q + n] + lg[(N - 1) * q + n:(N - 1) * q + 2 * n]
        # adjoints μ_i of the state terms, i = 1 … N
        c = np.zeros((N + 1, n))
        c[1:N] = 2 * lf * (ro.x[1:N] - x_ref) @ p.Q + lam_out @ p.DUo
        c[N] = lam_term
        mu = np.zeros((N + 1, n))
        mu[N] = c[N]
        for i in range(N - 1, 0, -1):
            mu[i] = c[i] + ro.A[i].T @ mu[i + 1]
        W = self.shoot.stage_hessians(ro, mu[1:])
        W[1:, :n, :n] += 2 * lf * p.Q
        S = ro.S[:N]
        ST = np.transpose(S, (0, 2, 1))
        SW = np.matmul(ST, W[:, :n, :n])
        Huu = SW.reshape(N * N * m, n).reshape(N, N * m, n)
        Huu = np.matmul(Huu.transpose(1, 0, 2).reshape(N * m, N * n),
                        S.reshape(N * n, N * m))
        C = np.matmul(ST, W[:, :n, n:])  # (N, Nm, m): ∂²/∂u ∂u_i of the x–u terms
        Ct = C.transpose(1, 0, 2).reshape(N * m, N * m)   # column block i = C[i]
        Huu += Ct + Ct.T
        Hv = Huu.reshape(N, m, N, m)
        stages = np.arange(N)
        Hv[stages, :, stages, :] += W[:, n:, n:] + 2 * lf * p.R
        if self._du_hess is not None:
            Huu += lf * self._du_hess
        return Huu

    def hessian_triu(self, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                     lg: np.ndarray) -> list:
        """The upper triangle of :meth:`hessian` (IPOPT's ``hess_lag``)."""
        return [self.hessian(wv, pv, lf, lg)[self._triu]]

    def hessian_convex(self, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                       lg: np.ndarray) -> list:
        """:meth:`hessian` with its eigenvalues clipped at :attr:`eigen_clip` (an SQP's QP
        needs it convex; LAPACK ``eigh``, ~40 µs for 31×31)."""
        H = self.hessian(wv, pv, lf, lg)
        if self.eigen_clip is not None:
            H = clip_eigenvalues(H, self.eigen_clip)
        return [H]

    def trajectory(self, wv: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """The states the solver's answer ``w`` gives (usually the last point evaluated)."""
        if self.kernel is not None:
            return self.kernel.xtraj(wv, pv)
        wv = np.asarray(wv, dtype=float).ravel()
        pv = np.asarray(pv, dtype=float).ravel()
        if self._key == (wv.tobytes(), pv.tobytes()):
            return self._ro.x
        p = self.p
        return self.shoot.rollout(pv[:p.n], wv[self.iu].reshape(p.N, p.m),
                                  derivatives=False).x

    def stop(self, *_: np.ndarray) -> list:
        """IPOPT's iteration callback: nonzero ("User_Requested_Stop") past the deadline."""
        return [np.array([1.0 if time.perf_counter() > self.deadline else 0.0])]

    # -- casadi -------------------------------------------------------------------------
    def ipopt_problem(self, ipopt_options: dict[str, Any],
                      time_budget: float | None) -> tuple[dict, dict]:
        """The casadi NLP and the ``nlpsol("ipopt")`` options with every callback."""
        p = self.p
        nw, npar, ng = p.nw, p.npar, self.ng
        sp = ca.Sparsity.dense
        cb = [
            NumpyCallback("fhocp_f", self.f, [sp(nw), sp(npar)], [sp(1)], ["x", "p"], ["f"]),
            NumpyCallback("fhocp_g", self.g, [sp(nw), sp(npar)], [sp(ng)], ["x", "p"], ["g"]),
            NumpyCallback("nlp_grad_f", self.gradient, [sp(nw), sp(npar)], [sp(1), sp(nw)],
                          ["x", "p"], ["f", "grad_f_x"]),
            NumpyCallback("nlp_jac_g", self.jacobian, [sp(nw), sp(npar)],
                          [sp(ng), sp(ng, nw)], ["x", "p"], ["g", "jac_g_x"]),
            NumpyCallback("nlp_hess_l", self.hessian_triu,
                          [sp(nw), sp(npar), sp(1), sp(ng)], [ca.Sparsity.upper(nw)],
                          ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
            NumpyCallback("time_budget", self.stop,
                          [sp(nw), sp(1), sp(ng), sp(nw), sp(ng), sp(npar)], [sp(1)],
                          ["x", "f", "g", "lam_x", "lam_g", "lam_p"], ["ret"]),
        ]
        self.callbacks += cb
        fcb, gcb, gradcb, jaccb, hesscb, stopcb = cb
        w = ca.MX.sym("w", nw)
        par = ca.MX.sym("p", npar)
        opts: dict[str, Any] = {"ipopt": dict(ipopt_options), "print_time": False,
                                "grad_f": gradcb, "jac_g": jaccb, "hess_lag": hesscb,
                                "no_nlp_grad": True, "calc_lam_p": False,
                                "calc_lam_x": False, "calc_f": False, "calc_g": False}
        if time_budget is not None:
            opts["iteration_callback"] = stopcb
        return {"x": w, "p": par, "f": fcb(w, par), "g": gcb(w, par)}, opts

    def sqp_problem(self, nlp: dict) -> tuple[dict, dict[str, Any]]:
        """The NLP and ``sqpmethod``'s derivative functions: the compiled kernel's
        ``external`` functions (``f``, ``g`` from its ``fg``) when there is a kernel, else
        ``nlp`` as it is and :meth:`sqp_functions`."""
        k = self.kernel
        if k is None:
            return nlp, self.sqp_functions()
        f, g = k.external("fg")(nlp["x"], nlp["p"])
        return ({"x": nlp["x"], "p": nlp["p"], "f": f, "g": g},
                {"jac_fg": k.external("jac_fg"), "hess_lag": k.external("hess_l")})

    def self_test(self, kernel: Any, clip: float | None, trials: int = 3,
                  seed: int = 12345) -> float:
        """Largest relative difference between ``kernel`` and these numpy functions at random
        points (:meth:`_self_test_point`): f, ∇f, g, ∂g/∂w, the clipped Hessian, the plain
        rollout, the observer's GRU step and the answer check (:meth:`_answer_check_pairs`);
        with the input-rate term when the problem has one (``u_{−1}`` drawn at random too)."""
        from controllers import gru

        p = self.p
        rng = np.random.default_rng(seed)
        n, m, N = p.n, p.m, p.N
        saved, self.eigen_clip = self.eigen_clip, None if clip is None else float(clip)
        worst = 0.0
        try:
            jac_c, hess_c = kernel.external("jac_fg"), kernel.external("hess_l")
            for _ in range(trials):
                wv, pv = self._self_test_point(rng)
                lg = rng.normal(0, 1, self.ng)
                pairs = list(zip(jac_c(wv, pv), self.jac_fg(wv, pv), strict=True))
                pairs.append((hess_c(wv, pv, 1.0, lg),
                              self.hessian_convex(wv, pv, np.array([1.0]), lg)[0]))
                u = wv[self.iu].reshape(N, m)
                x_np = self.shoot.rollout(pv[:n], u, derivatives=False).x
                pairs.append((kernel.simulate(pv[:n], u), x_np))
                dz, dr = rng.normal(0, 0.1, n), rng.normal(0, 0.1, n)
                pairs.append((kernel.gru_step(pv[:n], u[0], dz, dr),
                              gru.step(p.params, pv[:n], u[0], dz=dz, dr=dr)))
                pairs += self._answer_check_pairs(kernel, rng, u, pv, x_np)
                for a, b in pairs:
                    b = np.asarray(b, dtype=float)
                    a = np.asarray(a, dtype=float).reshape(b.shape)
                    scale = max(1.0, float(np.max(np.abs(b))))
                    worst = max(worst, float(np.max(np.abs(a - b))) / scale)
        finally:
            self.eigen_clip = saved
        return worst

    def _self_test_point(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A random ``(w, p)`` of :meth:`self_test`."""
        p = self.p
        wv = np.concatenate([rng.uniform(-1, 1, p.N * p.m), rng.uniform(0, 0.1, 1 + p.nsl)])
        pv = np.concatenate([rng.uniform(-0.5, 0.5, 2 * p.n),
                             rng.uniform(-1, 1, p.npar - 2 * p.n)])
        return wv, pv

    def _answer_check_pairs(self, kernel: Any, rng: np.random.Generator, u: np.ndarray,
                            pv: np.ndarray, x_np: np.ndarray) -> list[tuple[Any, Any]]:
        """(kernel, numpy) pairs of the answer check at ``(u, p)``: the kernel's rollout, its
        cost and residuals (:meth:`FixedSetpoint.evaluate <controllers.laws.paper.reference.
        FixedSetpoint.evaluate>`) against the law's ``cost`` and ``residuals``."""
        from controllers.ocp.fhocp_result import FHOCPResult, set_residuals

        p, n = self.p, self.p.n
        e_o, alpha = float(rng.uniform(0, 0.05)), float(rng.uniform(0, 0.5))
        x_bar, u_bar = self._reference(pv)
        u_prev = self._u_prev(pv)
        bounds = p.tightened_bounds(e_o)
        x_k, out = kernel.assess(pv[:n], u, x_bar, u_bar, bounds, alpha, u_prev)
        ref = FHOCPResult(u=u, x=x_np, cost=0.0, status="", success=False)
        p.reference.residuals(ref, x_np, bounds, pv[n:2 * n], alpha)
        got = FHOCPResult(u=u, x=x_k, cost=0.0, status="", success=False)
        set_residuals(got, out, alpha)
        return [(x_k, x_np),
                (np.array([out.cost, got.constraint_violation, got.terminal_violation,
                           got.softened]),
                 np.array([p.reference.plan_cost(x_np, u, x_bar, u_bar, bounds, alpha, u_prev),
                           ref.constraint_violation, ref.terminal_violation, ref.softened]))]

    def sqp_functions(self) -> dict[str, NumpyCallback]:
        """``sqpmethod``'s ``jac_fg`` (f, ∇f, g, ∂g/∂w) and full ``hess_lag`` (convexified),
        as numpy callbacks."""
        p = self.p
        nw, npar, ng = p.nw, p.npar, self.ng
        sp = ca.Sparsity.dense
        cb = [
            NumpyCallback("nlp_jac_fg", self.jac_fg, [sp(nw), sp(npar)],
                          [sp(1), sp(nw), sp(ng), sp(ng, nw)], ["x", "p"],
                          ["f", "grad_f_x", "g", "jac_g_x"]),
            NumpyCallback("nlp_hess_l", self.hessian_convex,
                          [sp(nw), sp(npar), sp(1), sp(ng)], [sp(nw, nw)],
                          ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"]),
        ]
        self.callbacks += cb
        return {"jac_fg": cb[0], "hess_lag": cb[1]}
