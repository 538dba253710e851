"""Where the tracking FHOCP's variables, constraints and parameters live in the solver's
buffers, and one solve's writing of them (:class:`TrackingLayout`, a part of
:class:`controllers.laws.tracking.reference.ArtificialSteadyState`).

``w = (u_0 … u_{M−1}, u_s, t[, ε])``, ``g`` = the paired output rows of stages ``1 … N−1``,
the terminal rows ``x_N − x_s ∓ t`` and the ``Y_s`` rows (softened: unpaired, with their
slacks, :mod:`controllers.ocp.soft`), ``p = (x̂, x_s0, r[, u_{−1}])``; the static bounds, the
tightened ones of each solve, the candidate as the initial guess and the warm start's
permutations.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from controllers.laws.tracking.reference import Target
    from controllers.ocp.fhocp import FHOCP

__all__ = ["TrackingLayout"]


class TrackingLayout:
    """The tracking reference's layout and buffer writing (its attributes: the FHOCP it
    serves, the control horizon, ``alpha_c``, ``us_rate``, ``ys_rhs``)."""

    def _layout(self, fh: FHOCP) -> None:
        """The layout of ``w``, ``g`` and ``p``, the static bounds and the warm start's
        permutations."""
        n, m, N, qr, M = fh.n, fh.m, fh.N, fh.qr, self.control_horizon
        self.nw = M * m + m + 1 + fh.nsl
        self.ius = np.arange(M * m, M * m + m)
        self.iu = np.vstack([np.arange(M * m).reshape(M, m),
                             np.tile(self.ius, (N - M, 1))]).astype(int)
        self.it = M * m + m
        self.ix = None
        self.ng = (N - 1) * qr + 2 * n + qr
        self.ng += fh.move_rows(self.iu[:M], self.ius, None, self.nw)   # eq:move-constraint
        self.npar = 2 * n + fh.p + (m if fh.has_du else 0)
        self.ys_base = self.ys_bounds - fh.Lbo          # Y_s: L U_o x_s <= rhs
        self._g_for: np.ndarray | None = None   # the bounds _lbg, _ubg were written for
        self._g_rows = self._constraint_rows()
        self._static_layout()

    def write(self, ins: dict[str, np.ndarray], x_hat: np.ndarray, e_o: float,
              request: Target) -> None:
        """``p = (x̂, x_s0, r[, u_{−1}])``, the bounds (the tightened rows, ``Y_s``, the
        move limit on ``u_s``), the candidate as the initial guess with ``t`` its terminal
        gap, and the multipliers shifted by one stage (``warm``) or zeros."""
        fh = self._fh
        pv = ins["p"]
        self._write_parameters(pv, x_hat, request.x_s0, request.r, request.u_prev)
        self._write_bounds(ins, e_o)
        op = fh.operator   # the operator's settings (controllers.ocp.operator_terms)
        if self.us_rate is not None:   # the steady input moves at most us_rate per step
            c = request.us_centre if op is None else np.minimum(np.maximum(
                request.us_centre, op.lo), op.hi)
            ins["lbx"][self.ius] = np.maximum(c - self.us_rate, -1.0)
            ins["ubx"][self.ius] = np.minimum(c + self.us_rate, 1.0)
        u_init = request.u_init
        if op is not None:
            op.bound(ins["lbx"], ins["ubx"], self.iu, self.ius)
            u_init = fh.prefix.impose(op.clip(u_init))
        fh.prefix.bound(ins["lbx"], ins["ubx"], self.iu)
        w0 = ins["x0"]
        w0[self.iu.ravel()] = u_init.ravel()
        w0[self.ius] = np.minimum(np.maximum(request.us_init, ins["lbx"][self.ius]),
                                  ins["ubx"][self.ius])
        if fh.softening:   # the slacks of the candidate's plan
            x = None if fh.kernel is not None else fh.simulate(x_hat, u_init)
            gap = fh.start_slacks(w0, pv, x, request.x_s0, self.steady_bounds(e_o),
                                  self.alpha_c)
        elif fh.kernel is not None:   # the rollout stays cached for the solve
            gap = fh.kernel.terminal_gap(w0, pv)
        else:
            gap = float(np.max(np.abs(fh.simulate(x_hat, u_init)[-1] - request.x_s0)))
        w0[self.it] = min(max(gap, 1e-6), self.alpha_c)
        warm = fh.warm_start
        if request.warm and warm is not None and fh.warm_duals:
            ins["lam_x0"][:] = warm["lam_x"][self.perm_x]
            ins["lam_g0"][:] = warm["lam_g"][self.perm_g]
        else:
            ins["lam_x0"][:] = 0.0
            ins["lam_g0"][:] = 0.0

    def _write_parameters(self, pv: np.ndarray, x_hat: Any, x_s0: Any, r: Any,
                          u_prev: Any) -> None:
        """``p = (x̂, x_s0, r[, u_{−1}])`` into ``pv`` (``u_{−1}`` only with the input-rate
        term)."""
        fh = self._fh
        n = fh.n
        pv[:n], pv[n:2 * n], pv[2 * n:2 * n + fh.p] = x_hat, x_s0, r
        if fh.has_du:
            pv[2 * n + fh.p:] = u_prev

    def _write_bounds(self, ins: dict[str, np.ndarray], e_o: float) -> None:
        """Variable and constraint bounds of one solve (the tightened rows for ``ê_o``)."""
        fh = self._fh
        ins["lbx"][:] = self._lbx
        ins["ubx"][:] = self._ubx
        bounds = fh.tightened_bounds(e_o)
        if self._g_for is not bounds:
            up_pos, up_idx, lo_pos, lo_idx = self._g_rows
            flat = bounds.ravel()
            self._ubg[up_pos] = flat[up_idx]
            self._lbg[lo_pos] = -flat[lo_idx]
            r0 = (fh.N - 1) * fh.qr + 2 * fh.n      # the Y_s rows
            ys = slice(r0, r0 + fh.qr)
            rhs = self.ys_rhs
            self._ubg[ys] = rhs[fh.pair_up]
            self._lbg[ys] = np.where(fh.pair_lo >= 0, -rhs[np.maximum(fh.pair_lo, 0)],
                                     -np.inf)
            self._g_for = bounds
        ins["lbg"][:] = self._lbg
        ins["ubg"][:] = self._ubg

    def _constraint_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The static constraint bounds (terminal and ``Y_s`` rows, into ``_lbg``/``_ubg``)
        and where the tightened bounds (N×q, rows i ≥ 1) go: ``(up_pos, up_idx, lo_pos,
        lo_idx)``, ``ubg[up_pos] = bounds.flat[up_idx]``, ``lbg[lo_pos] = −bounds.flat[
        lo_idx]`` (the output rows' paired bounds; unpaired lower bounds stay −∞)."""
        fh = self._fh
        N, qr, n, q = fh.N, fh.qr, fh.n, fh.q
        lbg = np.full(self.ng, -np.inf)
        ubg = np.full(self.ng, np.inf)
        r0 = (N - 1) * qr
        ubg[r0:r0 + n] = 0.0
        lbg[r0 + n:r0 + 2 * n] = 0.0                  # the Y_s rows: _write_bounds
        if fh.move is not None:                       # eq:move-constraint: the last rows
            lbg[-fh.nmv:], ubg[-fh.nmv:] = fh.move.lower, fh.move.upper
        self._lbg, self._ubg = lbg, ubg
        stage = np.arange(1, N)[:, None] * q
        up_idx = (stage + fh.pair_up[None, :]).ravel()
        has_lo = np.broadcast_to(fh.pair_lo >= 0, (N - 1, qr)).ravel()
        lo_idx = (stage + np.maximum(fh.pair_lo, 0)[None, :]).ravel()
        pos = np.arange(r0)
        return pos, up_idx, pos[has_lo], lo_idx[has_lo]

    def _static_layout(self) -> None:
        """The variable bounds and the permutations that shift ``w`` and the multipliers by
        one stage (the warm start)."""
        fh = self._fh
        lbx = np.full(self.nw, -1.0)
        ubx = np.full(self.nw, 1.0)
        lbx[self.it], ubx[self.it] = 0.0, self.alpha_c
        lbx[self.it + 1:], ubx[self.it + 1:] = 0.0, np.inf   # the slacks (softened rows)
        self._lbx, self._ubx = lbx, ubx
        px = np.arange(self.nw)
        free = self.iu[:self.control_horizon]
        px[free[:-1].ravel()] = free[1:].ravel()
        if self.control_horizon < fh.N:   # the last free input takes u_s's value
            px[free[-1]] = self.ius
        self.perm_x = px
        N, qr = fh.N, fh.qr
        pg = np.arange(self.ng)
        if N > 1:
            blk = np.arange((N - 1) * qr).reshape(N - 1, qr)
            pg[: (N - 1) * qr] = np.vstack([blk[1:], blk[-1:]]).ravel()
        if fh.move is not None:
            pg[self.ng - fh.nmv:] = self.ng - fh.nmv + fh.move.permutation()
        self.perm_g = pg
