"""Single-shooting rollout of the GRU ``eq:gru`` with exact first and second derivatives (numpy).

For a horizon of ``N`` stages and inputs ``u_0 … u_{N−1}`` from ``x_0``:

* the states ``x_i`` and stage Jacobians ``A_i = ∂f/∂x``, ``B_i = ∂f/∂u``;
* the sensitivities ``S_i = ∂x_i/∂(u_0 … u_{N−1})`` (``S_{i+1} = A_i S_i + B_i E_i``);
* for adjoints ``μ_{i+1}``, the stage Hessians ``W_i = ∇²_{(x,u)} μ_{i+1}ᵀ f(x_i, u_i)``,
  from which the exact Hessian of any Lagrangian ``Σ_i φ_i(x_i) + ψ(u)`` follows as
  ``Σ_i S_iᵀ ∇²φ_i S_i + Σ_i Z_iᵀ W_i Z_i + ∇²ψ`` with ``Z_i = [S_i; E_i]``.

Why hand-written: the FHOCP of ``eq:optimization`` needs these matrices a few times per
controller step; as casadi SX scalar graphs they cost 27 k (Jacobian) and 78 k (Hessian)
instructions per stage (0.6 ms and 1.8 ms per horizon, even compiled 0.13 ms and 0.38 ms), while
written as dense matrix products (BLAS) they take a few microseconds per stage. The state
update itself is :func:`controllers.gru.step` (the one source of the equations); the derivative
formulas below are checked against casadi's automatic differentiation of that same function
in ``tests/controllers/ocp/test_shooting.py``.

Derivatives of ``f = h + z∘(x − h)`` with ``z = σ(a_z)``, ``r = σ(a_r)``, ``ρ = r∘x``,
``h = tanh(a_h)``, ``a_h = W_h u + U_h ρ + b_h`` (``v = (x, u)``, ``D· = ∂·/∂v``)::

    D_z = diag(z') J_z,   D_r = diag(r') J_r,   D_ρ = diag(x) D_r + [diag(r) 0]
    J_h = U_h D_ρ + [0 W_h],   D_h = diag(h') J_h,   D_x = [I 0]
    D_f = [A B] = diag(x − h) D_z + diag(z) D_x + diag(1 − z) D_h

    ∇²(μᵀf) = J_hᵀ diag(μ(1−z)h'') J_h + J_rᵀ diag(ν r'' x) J_r
              + J_rᵀ diag(ν r') D_x + D_xᵀ diag(ν r') J_r + J_zᵀ diag(μ (x−h) z'') J_z
              + D_zᵀ diag(μ) (D_x − D_h) + (D_x − D_h)ᵀ diag(μ) D_z,
    ν = U_hᵀ (μ (1−z) h'),  J_z = [U_z W_z],  J_r = [U_r W_r]

with ``z' = z(1−z)``, ``z'' = z'(1−2z)`` (same for r) and ``h' = 1−h²``, ``h'' = −2h h'``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.special import expit

from controllers import gru

__all__ = ["GRUShooting", "Rollout"]


@dataclass
class Rollout:
    """States, gates and first derivatives of one rollout (see the module docstring).

    Attributes
    ----------
    x : (N + 1, n) array
        States ``x_0 … x_N``.
    u : (N, m) array
    z, r, h : (N, n) arrays
        Gates of each stage.
    D : dict of (N, n, n + m) arrays
        ``"z"``, ``"r"``, ``"h"`` (``D_z``, ``D_r``, ``D_h``), ``"Jh"`` (``J_h``) per stage.
    A : (N, n, n) array
    B : (N, n, m) array
    S : (N + 1, n, N m) array
        Sensitivities ``∂x_i/∂u``.
    """

    x: np.ndarray
    u: np.ndarray
    z: np.ndarray
    r: np.ndarray
    h: np.ndarray
    D: dict
    A: np.ndarray
    B: np.ndarray
    S: np.ndarray


class GRUShooting:
    """Rollouts of ``eq:gru`` over a fixed horizon with exact derivatives.

    Parameters
    ----------
    params : mapping of arrays
        GRU weights.
    N : int
        Horizon.
    """

    def __init__(self, params: Mapping[str, np.ndarray], N: int) -> None:
        self.P = {k: np.asarray(v, dtype=float) for k, v in params.items()}
        self.n, self.m, _ = gru.dimensions(self.P)
        self.N = int(N)
        P = self.P
        self.Jz = np.hstack([P["U_z"], P["W_z"]])
        self.Jr = np.hstack([P["U_r"], P["W_r"]])
        n, m = self.n, self.m
        self.Dx = np.hstack([np.eye(n), np.zeros((n, m))])
        self._W_h_pad = np.hstack([np.zeros((n, n)), P["W_h"]])
        self._W_zrh = np.vstack([P["W_z"], P["W_r"], P["W_h"]])
        self._U_zr = np.vstack([P["U_z"], P["U_r"]])
        self.refresh()

    def refresh(self) -> None:
        """Read the biases again (moved in place by
        :class:`controllers.disturbances.BiasShift`)."""
        P = self.P
        self._b_zrh = np.concatenate([P["b_z"], P["b_r"], P["b_h"]])

    def rollout(self, x0: np.ndarray, u: np.ndarray, derivatives: bool = True) -> Rollout:
        """Simulate from ``x0`` with inputs ``u`` (N, m); optionally with ``A, B, S``."""
        P, N, n, m = self.P, self.N, self.n, self.m
        x = np.empty((N + 1, n))
        x[0] = x0
        z = np.empty((N, n))
        r = np.empty((N, n))
        h = np.empty((N, n))
        # input terms of all stages at once; one (2n × n) product per stage for z and r
        a_u = u @ self._W_zrh.T + self._b_zrh          # (N, 3n)
        U_zr, U_h = self._U_zr, P["U_h"]
        a_zr, a_h = a_u[:, : 2 * n], a_u[:, 2 * n:]
        for i in range(N):
            xi = x[i]
            zr = expit(a_zr[i] + U_zr @ xi)
            zi = zr[:n]
            z[i] = zi
            r[i] = zr[n:]
            hi = np.tanh(a_h[i] + U_h @ (zr[n:] * xi))
            h[i] = hi
            x[i + 1] = hi + zi * (xi - hi)
        if not derivatives:
            return Rollout(x, u, z, r, h, {}, np.empty(0), np.empty(0), np.empty(0))
        xs = x[:N]
        zp = z * (1 - z)
        rp = r * (1 - r)
        hp = 1 - h * h
        Dz = zp[:, :, None] * self.Jz[None]
        Dr = rp[:, :, None] * self.Jr[None]
        Drho = xs[:, :, None] * Dr
        Drho[:, :, :n] += r[:, :, None] * np.eye(n)[None]
        Jh = np.matmul(P["U_h"][None], Drho) + self._W_h_pad[None]
        Dh = hp[:, :, None] * Jh
        Df = (xs - h)[:, :, None] * Dz + (1 - z)[:, :, None] * Dh
        Df[:, :, :n] += z[:, :, None] * np.eye(n)[None]
        A = Df[:, :, :n]
        B = Df[:, :, n:]
        S = np.zeros((N + 1, n, N * m))
        for i in range(N):
            if i:
                S[i + 1, :, : i * m] = A[i] @ S[i, :, : i * m]
            S[i + 1, :, i * m:(i + 1) * m] = B[i]
        return Rollout(x, u, z, r, h, {"z": Dz, "r": Dr, "h": Dh, "Jh": Jh}, A, B, S)

    def stage_hessians(self, ro: Rollout, mu: np.ndarray) -> np.ndarray:
        """``W_i = ∇²_{(x,u)} μ_{i+1}ᵀ f(x_i, u_i)`` for adjoints ``mu`` (N, n) → (N, n+m, n+m)."""
        P, n = self.P, self.n
        xs = ro.x[: self.N]
        z, r, h = ro.z, ro.r, ro.h
        zp = z * (1 - z)
        rp = r * (1 - r)
        hp = 1 - h * h
        zpp = zp * (1 - 2 * z)
        rpp = rp * (1 - 2 * r)
        hpp = -2 * h * hp
        Dz, Dh, Jh = ro.D["z"], ro.D["h"], ro.D["Jh"]
        nu = (mu * (1 - z) * hp) @ P["U_h"]            # (N, n): U_hᵀ (μ(1−z)h') per stage

        def quad(J: np.ndarray, d: np.ndarray) -> np.ndarray:
            """Jᵀ diag(d) J per stage; J is (N, n, k) or (n, k)."""
            if J.ndim == 2:
                return np.matmul(np.transpose(J[None] * d[:, :, None], (0, 2, 1)), J)
            return np.matmul(np.transpose(J * d[:, :, None], (0, 2, 1)), J)

        W = quad(Jh, mu * (1 - z) * hpp)
        W += quad(self.Jr, nu * rpp * xs)
        W += quad(self.Jz, mu * (xs - h) * zpp)
        DzT_mu = np.transpose(Dz * mu[:, :, None], (0, 2, 1))   # D_zᵀ diag(μ), (N, n+m, n)
        T = -np.matmul(DzT_mu, Dh)                              # D_zᵀ diag(μ)(−D_h)
        T[:, :, :n] += DzT_mu                                    # D_zᵀ diag(μ) D_x
        T[:, :n, :] += (nu * rp)[:, :, None] * self.Jr[None]     # D_xᵀ diag(ν r') J_r
        W += T + np.transpose(T, (0, 2, 1))
        return W
