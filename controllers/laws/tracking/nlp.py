"""The tracking FHOCP as a single-shooting NLP with exact numpy derivatives (the kernel's twin).

Decision variables ``w = (u_0 … u_{M−1}, u_s, t)``: the free inputs (``u_i = u_s`` for
``i ≥ M``, the control horizon ``M ≤ N``), the artificial steady input ``u_s`` and the
epigraph variable ``t``; ``x_s = x_s(u_s)`` is implicit
(:func:`controllers.ocp.steady_state.steady_state`, Newton from the parameter ``x_s0``).
Parameters ``p = (x̂, x_s0, r)``, then ``u_{−1}`` with an input-rate term; ``r = ȳ − d̂`` is
the set-point the steady output should reach (the offset-free target). Cost::

    Σ_{i<N} ‖x_i − x_s‖²_Q + ‖u_i − u_s‖²_R + s t² + ‖U_o x_s + b_o − r‖²_T
      [+ Σ_{i<N} ‖u_i − u_{i−1}‖²_S + ‖u_{N−1} − u_s‖²_S]

Constraints, in this order: the paired output rows ``D U_o x_i`` (``i = 1 … N−1``, tightened
as in ``eq:optimization-constraint``), ``x_N − x_s ∓ t`` (the terminal set ``t ≤ α_c``) and
``D U_o x_s`` (the steady output in ``Y_s``). The Hessian is exact: its ``u_s`` block includes
the curvature of ``x_s(u_s)`` (``λᵀ ∂²x_s/∂u_s²``, :meth:`TrackingNLP._curvature`; without it
the SQP converged linearly, 25 iterations instead of 10 on a set-point step). The compiled
kernel (``HAS_ASS``) computes the same; :meth:`self_test` compares them.

The derivatives are computed for the expanded vector ``w_N = (u_0 … u_{N−1}, u_s, t)``, every
``u_i`` its own variable, and mapped back by the chain rule: ``w_N = E w`` with ``E`` the 0/1
matrix that copies ``u_s`` into the tail, ``∇f = Eᵀ ∇_N f``, ``∂g/∂w = ∂g/∂w_N E``,
``∇²L = Eᵀ ∇²_N L E`` (the kernel computes the reduced ones directly).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.ocp.input_rate import du_cost
from controllers.ocp.nlp_single_shooting import SingleShootingNLP
from controllers.ocp.steady_state import steady_state

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["TrackingNLP"]


class TrackingNLP(SingleShootingNLP):
    """Function and derivative evaluations of an FHOCP with the tracking law's reference
    (:class:`~controllers.laws.tracking.reference.ArtificialSteadyState`; see the module
    docstring); a kernel workspace as for the parent."""

    def __init__(self, fhocp: FHOCP, kernel: Any = None) -> None:
        super().__init__(fhocp, kernel)
        ass = fhocp.reference   # the artificial steady state
        self.p: Any = fhocp
        self.ius = ass.ius
        #: the offset weights ``T``
        self.T = ass.offset_weight
        from controllers.ocp.shooting import GRUShooting

        #: one stage at (x_s, u_s): the second derivatives of the curvature term
        self._one_stage = GRUShooting(fhocp.params, 1)
        self._xs_key: bytes | None = None
        self._xs: tuple[np.ndarray, np.ndarray, bool] = (np.zeros(0), np.zeros(0), False)
        # the expanded vector w_N = E w (every u_i its own variable): its indices, and E
        N, m = fhocp.N, fhocp.m
        self._iuf = np.arange(N * m)
        self._iusf = np.arange(N * m, N * m + m)
        self._itf = N * m + m
        self._nwf = N * m + m + 1
        self._E: np.ndarray | None = None   # None: w_N = w (no control horizon)
        if ass.control_horizon < N:
            src = np.concatenate([fhocp.iu.ravel(), ass.ius, [fhocp.it]])
            self._E = np.zeros((self._nwf, self.nwh))
            self._E[np.arange(self._nwf), src] = 1.0

    def forget(self) -> None:
        super().forget()
        self._xs_key = None
        self._one_stage.refresh()

    # -- one point ----------------------------------------------------------------------
    def steady(self, wv: np.ndarray, pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x_s, X_s)`` at ``(w, p)`` (cached per ``(u_s, x_s0)``)."""
        p = self.p
        us, x0 = wv[self.ius], pv[p.n:2 * p.n]
        key = us.tobytes() + x0.tobytes()
        if key != self._xs_key:
            self._xs = steady_state(p.params, us, x0)
            self._xs_key = key
        return self._xs[0], self._xs[1]

    def _target(self, pv: np.ndarray) -> np.ndarray:
        n = self.p.n
        return pv[2 * n:2 * n + self.p.p]

    def _u_prev(self, pv: np.ndarray) -> np.ndarray | None:
        p = self.p
        return pv[2 * p.n + p.p:] if p.has_du else None

    def _offset(self, xs: np.ndarray, pv: np.ndarray) -> np.ndarray:
        P = self.p.params
        return P["U_o"] @ xs + P["b_o"] - self._target(pv)

    def objective(self, wv: np.ndarray, pv: np.ndarray, ro: Any) -> float:
        p = self.p
        xs, _ = self.steady(wv, pv)
        us = wv[self.ius]
        dx = ro.x[: p.N] - xs
        du = ro.u - us
        e = self._offset(xs, pv)
        J = float(np.vdot(dx @ p.Q, dx) + np.vdot(du @ p.R, du)
                  + p.s * float(wv[p.it]) ** 2 + np.vdot(e * self.T, e))
        if p.has_du:
            J += du_cost(ro.u, self._u_prev(pv), p.du_weight)
            J += float(np.vdot((ro.u[-1] - us) * p.du_weight, ro.u[-1] - us))
        return J

    def constraints(self, wv: np.ndarray, pv: np.ndarray, ro: Any) -> np.ndarray:
        p = self.p
        xs, _ = self.steady(wv, pv)
        t = wv[p.it]
        dN = ro.x[p.N] - xs
        return np.concatenate([(ro.x[1:p.N] @ p.DUo.T).ravel(), dN - t, dN + t,
                               p.DUo @ xs])

    def _dcost_dxs(self, ro: Any, xs: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """The explicit ``∂J/∂x_s``."""
        p = self.p
        e = self._offset(xs, pv)
        return (-2 * np.sum(ro.x[: p.N] - xs, axis=0) @ p.Q
                + p.params["U_o"].T @ (2 * self.T * e))

    def _grad_us(self, wv: np.ndarray, ro: Any, Xs: np.ndarray, lx: np.ndarray,
                 grad: np.ndarray) -> None:
        """The ``u_s`` entries of the expanded gradient (``grad``: ``w_N``'s)."""
        p = self.p
        us = wv[self.ius]
        grad[self._iusf] = Xs.T @ lx - np.sum(ro.u - us, axis=0) @ (2 * p.R)
        if p.has_du:
            d = 2 * p.du_weight * (ro.u[-1] - us)
            grad[self._iuf[-p.m:]] += d
            grad[self._iusf] -= d

    def _gradient(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[f, ∇f]`` of the hard problem."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        xs, Xs = self.steady(wv, pv)
        grad = np.zeros(self._nwf)
        grad[self._iuf] = self.stage_gradient(ro, xs, wv[self.ius], pv)
        self._grad_us(wv, ro, Xs, self._dcost_dxs(ro, xs, pv), grad)
        grad[self._itf] = 2 * p.s * wv[p.it]
        return [self.objective(wv, pv, ro), grad if self._E is None else grad @ self._E]

    def _jacobian(self, wv: np.ndarray, pv: np.ndarray) -> list:
        """``[g, ∂g/∂w]`` of the hard problem."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        _, Xs = self.steady(wv, pv)
        N, n, q, iu, ius, it = p.N, p.n, p.qr, self._iuf, self._iusf, self._itf
        r0 = (N - 1) * q
        J = np.zeros((self.ng_law, self._nwf))
        J[:r0, iu] = np.matmul(p.DUo[None], ro.S[1:N]).reshape(r0, N * p.m)
        J[r0:r0 + n, iu] = ro.S[N]
        J[r0 + n:r0 + 2 * n, iu] = ro.S[N]
        J[r0:r0 + n, it] = -1.0
        J[r0 + n:r0 + 2 * n, it] = 1.0
        J[r0:r0 + n, ius] = -Xs
        J[r0 + n:r0 + 2 * n, ius] = -Xs
        J[r0 + 2 * n:, ius] = p.DUo @ Xs
        return [self.constraints(wv, pv, ro), J if self._E is None else J @ self._E]

    def _hessian(self, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                 lg: np.ndarray) -> np.ndarray:
        """The exact Hessian of the hard problem's Lagrangian (dense, symmetric)."""
        p = self.p
        ro = self.rollout(wv, pv, True)
        xs, Xs = self.steady(wv, pv)
        N, m, iu, ius = p.N, p.m, self._iuf, self._iusf
        lf0 = float(lf[0])
        # the input block: the paper's FHOCP's with x̄ = x_s held fixed
        H = np.zeros((self._nwf, self._nwf))
        H[np.ix_(iu, iu)] = self.input_hessian(ro, xs, lf0, lg)
        S = ro.S[1:N]                                      # (N − 1, n, N m)
        cross = -np.einsum("ikc,kj->cj", S, 2 * p.Q @ Xs)  # Σ S_iᵀ (−2Q) X_s
        cross -= np.tile(2 * p.R, (N, 1))
        if p.has_du:
            cross[(N - 1) * m:] -= 2 * np.diag(p.du_weight)
            H[np.ix_(iu[-m:], iu[-m:])] += lf0 * 2 * np.diag(p.du_weight)
        M = 2 * N * p.Q + p.params["U_o"].T @ (2 * self.T[:, None]
                                                * p.params["U_o"])
        Hs = Xs.T @ M @ Xs + 2 * N * p.R
        if p.has_du:
            Hs += 2 * np.diag(p.du_weight)
        H[np.ix_(iu, ius)] = lf0 * cross
        H[np.ix_(ius, iu)] = lf0 * cross.T
        H[np.ix_(ius, ius)] = lf0 * Hs + self._curvature(wv, pv, ro, xs, Xs, lf0, lg)
        H[self._itf, self._itf] = 2 * lf0 * p.s
        return H if self._E is None else self._E.T @ H @ self._E

    def _curvature(self, wv: np.ndarray, pv: np.ndarray, ro: Any, xs: np.ndarray,
                   Xs: np.ndarray, lf: float, lg: np.ndarray) -> np.ndarray:
        """``λᵀ ∂²x_s/∂u_s²`` (λ = ∂L/∂x_s): ``Zᵀ ∇²(μᵀ f) Z``, ``Z = [X_s; I]``,
        ``μ = (I − A_s)^{-T} λ``."""
        from controllers.equilibrium import jacobians

        p = self.p
        N, n, q = p.N, p.n, p.qr
        r0 = (N - 1) * q
        lx = lf * self._dcost_dxs(ro, xs, pv) - lg[r0:r0 + n] - lg[r0 + n:r0 + 2 * n] + (
            p.DUo.T @ lg[r0 + 2 * n:r0 + 2 * n + q])
        A, _ = jacobians(p.params, xs, wv[self.ius])
        mu = np.linalg.solve((np.eye(n) - A).T, lx)
        one = self._one_stage.rollout(xs, wv[self.ius][None], derivatives=True)
        W = self._one_stage.stage_hessians(one, mu[None])[0]
        Z = np.vstack([Xs, np.eye(p.m)])
        return Z.T @ W @ Z

    def _self_test_point(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A random ``(w, p)`` of :meth:`SingleShootingNLP.self_test` against the ``HAS_ASS``
        kernel: ``x_s0`` near ``x̂`` (Newton's start), ``u_s`` inside the input box."""
        p = self.p
        n, m = p.n, p.m
        us = rng.uniform(-0.8, 0.8, m)
        x0 = rng.uniform(-0.3, 0.3, n)
        wv = np.concatenate([rng.uniform(-1, 1, p.reference.control_horizon * m), us,
                             rng.uniform(0, 0.1, 1 + p.nsl)])
        pv = np.concatenate([x0, x0 + rng.normal(0, 0.01, n),
                             rng.uniform(-1, 1, p.npar - 2 * n)])
        return wv, pv

    def _answer_check_pairs(self, kernel: Any, rng: np.random.Generator, u: np.ndarray,
                            pv: np.ndarray, x_np: np.ndarray) -> list[tuple[Any, Any]]:
        """None: the tracking FHOCP's answer check
        (:meth:`~controllers.laws.tracking.reference.ArtificialSteadyState.evaluate`) is its
        own (the plain rollout, compared above, and ``x_s`` verified by a numpy GRU step), not
        the kernel's ``assess``."""
        return []
