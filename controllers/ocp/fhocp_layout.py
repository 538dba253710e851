"""Where the FHOCP's variables and constraints live in the solver's vectors, and warm starts.

``w`` holds the decision variables, ``g`` the constraints, ``p = (x̂, x̄, ū)`` the
parameters, followed by ``u_{−1}`` (the previously applied input) when the cost has an
input-rate term (``FHOCP.has_du``). Single shooting: ``w = (u_0 … u_{N−1}, t[, ε])``, ``g`` =
the paired output rows ``D U_o x_i`` (``i = 1 … N−1``) then ``x_N − x̄ ∓ t`` (softened:
unpaired rows with their slacks ``ε``, :mod:`controllers.ocp.soft`). Multiple shooting:
``w`` in stage order ``(x_0, u_0, x_1, …, x_N, t)``, ``g`` = ``x_0 − x̂``, the dynamics
defects, the output rows (``i = 0 … N−1``) then the terminal rows.

:meth:`FHOCPLayout.write` fills the solver's argument buffers for one solve: the bounds
(tightened with ``ê_o``, the terminal set ``t ≤ α``), the parameters, and the warm start: the
previous solution shifted by one stage with ``ū`` appended, its multipliers shifted the same
way (index permutations computed once).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["FHOCPLayout"]


class FHOCPLayout:
    """Index sets of ``w`` and ``g`` for one FHOCP and formulation.

    Attributes
    ----------
    nw : int
        Number of decision variables.
    iu : (N, m) int array
        Indices of ``u_i`` in ``w``.
    it : int
        Index of the epigraph variable ``t``.
    ix : (N + 1, n) int array or None
        Indices of ``x_i`` in ``w`` (multiple shooting only).
    ng : int
        Number of constraints.
    lbx, ubx : arrays
        Bounds of ``w`` (``‖u‖∞ ≤ 1``, ``t ≥ 0``; ``t ≤ α`` is set per solve).
    """

    def __init__(self, fhocp: FHOCP, single_shooting: bool) -> None:
        p = fhocp
        n, m, N, q, qr = p.n, p.m, p.N, p.q, p.qr
        self.single = single_shooting
        if single_shooting:
            self.nw = N * m + 1 + p.nsl
            self.iu = np.arange(N * m).reshape(N, m)
            self.it = N * m
            self.ix = None
            self.ng = (N - 1) * qr + 2 * n
            self.ng += p.move_rows(self.iu, None, np.arange(2 * n, 2 * n + m), self.nw)
        else:
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
            self.ng = (N + 1) * n + N * q + 2 * n
        self.lbx = np.full(self.nw, -np.inf)
        self.ubx = np.full(self.nw, np.inf)
        self.lbx[self.iu.ravel()] = -1.0
        self.ubx[self.iu.ravel()] = 1.0
        self.lbx[self.it] = 0.0
        self.lbx[self.it + 1:] = 0.0   # the slacks ε ≥ 0 (softened rows)
        self._constraint_rows(p)
        self._shifts(p)

    def _constraint_rows(self, p: FHOCP) -> None:
        """Constant parts of ``lbg``/``ubg`` and where the tightened bounds go."""
        n, N, q, qr = p.n, p.N, p.q, p.qr
        self._lbg0 = np.full(self.ng, -np.inf)
        self._ubg0 = np.full(self.ng, np.inf)
        self._g_bounds: np.ndarray | None = None   # the bounds self._lbg, self._ubg hold
        if self.single:
            rows = np.arange(1, N)[:, None]
            self._up_idx = (rows * q + p.pair_up[None, :]).ravel()  # into bounds.ravel()
            self._lo_has = np.tile(p.pair_lo >= 0, N - 1)
            self._lo_idx = (rows * q + np.maximum(p.pair_lo, 0)[None, :]).ravel()
            off = (N - 1) * qr
        else:
            neq = (N + 1) * n
            self._lbg0[:neq] = 0.0
            self._ubg0[:neq] = 0.0
            self._up_idx = np.arange(N * q)
            off = neq + N * q
        self._rows = slice(off - self._up_idx.size, off)
        self._ubg0[off: off + n] = 0.0
        self._lbg0[off + n: off + 2 * n] = 0.0
        if p.move is not None:   # eq:move-constraint: the last rows
            self._lbg0[-p.nmv:] = p.move.lower
            self._ubg0[-p.nmv:] = p.move.upper

    def _shifts(self, p: FHOCP) -> None:
        """Permutations that shift ``w`` and the multipliers by one stage (the last stage
        keeps its values; the shifted primal gets ``ū`` appended)."""
        N, qr, m = p.N, p.qr, p.m
        iu = self.iu
        px = np.arange(self.nw)
        px[iu[:-1].ravel()] = iu[1:].ravel()
        if self.ix is not None:
            px[self.ix[:-1].ravel()] = self.ix[1:].ravel()
        self.perm_x = px
        pg = np.arange(self.ng)
        if self.single:
            blk = np.arange((N - 1) * qr).reshape(N - 1, qr)
            pg[: (N - 1) * qr] = np.vstack([blk[1:], blk[-1:]]).ravel()
        if p.move is not None:
            pg[self.ng - p.nmv:] = self.ng - p.nmv + p.move.permutation()
        self.perm_g = pg
        self._u_next = iu[1:].ravel()  # u_1 … u_{N−1} of the previous solution
        self._iu_flat = iu.ravel()
        self._m = m

    def write(self, ins: dict[str, np.ndarray], bounds: np.ndarray, x_hat: np.ndarray,
              x_bar: np.ndarray, u_bar: np.ndarray, alpha: float, u_init: np.ndarray | None,
              prev: dict[str, np.ndarray] | None, warm_duals: bool,
              simulate: Callable[[np.ndarray, np.ndarray], Any],
              u_prev: np.ndarray | None = None, prefix: Any = None,
              slacks: Callable[..., None] | None = None, operator: Any = None) -> np.ndarray:
        """Fill the solver's argument buffers for one solve; returns the initial inputs.

        Parameters
        ----------
        ins : dict of arrays
            The solver's argument buffers (``x0``, ``p``, ``lbx``, ``ubx``, ``lbg``,
            ``ubg``, ``lam_x0``, ``lam_g0``), written in place.
        bounds : (N, q) array
            The tightened output bounds (:meth:`controllers.ocp.fhocp.FHOCP.tightened_bounds`).
        u_init : (N, m) array, optional
            Initial inputs; default the previous solution shifted (``ū`` appended), else ``ū``.
        prev : dict, optional
            The previous solve's ``w``, ``lam_x``, ``lam_g`` (``None``: a cold start).
        simulate : callable
            ``(x̂, u) → x_0 … x_N``: the rollout for the initial ``t`` (and states).
        u_prev : (m,) array, optional
            ``u_{−1}``, written after ``ū`` (only for a problem with an input-rate term).
        prefix : InputPrefix, optional
            The inputs already applied (:attr:`controllers.ocp.fhocp.FHOCP.prefix`): fixed in
            the bounds and in the initial inputs.
        slacks : callable, optional
            A softened problem's :meth:`~controllers.ocp.fhocp.FHOCP.start_slacks`: the
            initial slacks are the initial plan's.
        operator : OperatorTerms, optional
            The operator's bounds on the inputs (:attr:`controllers.ocp.fhocp.FHOCP.
            operator`), before the inputs already applied; the initial inputs inside them.
        """
        n, m = x_hat.shape[0], self._m
        p = ins["p"]
        p[:n] = x_hat
        p[n:2 * n] = x_bar
        p[2 * n:2 * n + m] = u_bar
        if u_prev is not None:
            p[2 * n + m:] = u_prev
        ins["lbx"][:] = self.lbx
        ubx = ins["ubx"]
        ubx[:] = self.ubx
        ubx[self.it] = alpha
        if self._g_bounds is not bounds:   # the same bounds object: the same rows
            flat = bounds.ravel()
            lbg, ubg = self._lbg0.copy(), self._ubg0.copy()
            ubg[self._rows] = flat[self._up_idx]
            if self.single:
                lbg[self._rows] = np.where(self._lo_has, -flat[self._lo_idx], -np.inf)
            self._g_bounds, self._lbg, self._ubg = bounds, lbg, ubg
        ins["lbg"][:] = self._lbg
        ins["ubg"][:] = self._ubg
        if u_init is None:
            if prev is not None:
                u = np.concatenate([prev["w"][self._u_next], u_bar])
            else:
                u = np.tile(u_bar, self.iu.shape[0])
        else:
            u = np.asarray(u_init, dtype=float).ravel()
        u = np.clip(u, -1.0, 1.0).reshape(-1, m)
        if operator is not None:   # the operator's settings (controllers.ocp.operator_terms)
            operator.bound(ins["lbx"], ubx, self.iu)
            u = operator.clip(u)
        if prefix is not None:
            u = prefix.impose(u)
            prefix.bound(ins["lbx"], ubx, self.iu)
        x = simulate(x_hat, u)
        x0 = ins["x0"]
        x0[:] = 0.0
        x0[self._iu_flat] = u.ravel()
        gap = float(np.max(np.abs(x[-1] - x_bar)))
        x0[self.it] = min(max(gap, 1e-6), max(alpha, 0.0))
        if slacks is not None:
            slacks(x0, p, x, x_bar, bounds, alpha)
        if self.ix is not None:
            x0[self.ix] = x
        if prev is not None and warm_duals:
            ins["lam_x0"][:] = prev["lam_x"][self.perm_x]
            ins["lam_g0"][:] = prev["lam_g"][self.perm_g]
        else:
            ins["lam_x0"][:] = 0.0
            ins["lam_g0"][:] = 0.0
        return u
