"""The input-rate (Δu) penalty of the FHOCP, outside the paper's cost (issue 20, "smooth
inputs"): its weights, value and exact derivatives in numpy.

    J_Δu(u; u_{−1}) = Σ_{i=0}^{N−1} (u_i − u_{i−1})ᵀ S (u_i − u_{i−1}),   S = diag(s_1 … s_m) ⪰ 0

in normalised units, with ``u_{−1}`` the input applied at the previous step (a parameter of
the solve: :class:`controllers.ocp.fhocp.FHOCP` puts it at the end of ``p``). Stacking
``u = (u_0 … u_{N−1})`` and ``Δ = D u − E u_{−1}`` (``D`` the block difference operator, ``E``
the first block of the identity), ``J_Δu = Δᵀ (I ⊗ S) Δ``: the gradient is
``2 Dᵀ (I ⊗ S) Δ``, i.e. ``2 S (Δ_i − Δ_{i+1})`` for stage ``i`` (``Δ_N = 0``), and the Hessian
``2 Dᵀ (I ⊗ S) D`` is constant and block tridiagonal: ``4 S`` on the diagonal blocks (``2 S``
on the last one) and ``−2 S`` next to them. The compiled kernel
(``controllers/kernel/derivatives.c``: ``du_cost``, ``du_gradient``, ``du_hessian``) does the
same sums; its self-test compares them with these.

With all weights zero (the default) the term does not exist: no parameter, no code path,
the paper's law bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from controllers.errors import DesignError

__all__ = ["MoveRows", "du_cost", "du_gradient", "du_hessian", "du_weights", "move_limit"]


def du_weights(value: Any, m: int, names: Sequence[str] | None = None) -> np.ndarray:
    """The diagonal of ``S`` (m,) from a number (every input), a sequence of ``m`` numbers,
    or, with ``names``, a mapping ``{input name: weight}`` (inputs not named: 0).

    Parameters
    ----------
    value : float, sequence of float or mapping
        The weights, normalised units.
    m : int
        Number of inputs.
    names : sequence of str, optional
        The inputs' names (needed for a mapping).

    Raises
    ------
    DesignError
        A negative, non-finite or non-numeric weight, a wrong length or an unknown name (one
        line).
    """
    def number(v: Any) -> bool:
        return (isinstance(v, int | float | np.integer | np.floating) and not isinstance(
            v, bool) and math.isfinite(float(v)) and float(v) >= 0.0)

    if isinstance(value, Mapping):
        if names is None:
            raise DesignError("du_weight: a mapping needs the inputs' names")
        unknown = [str(k) for k in value if k not in names]
        if unknown:
            raise DesignError(f"du_weight: unknown input {unknown[0]!r} (inputs: "
                              f"{', '.join(names)})")
        bad = [k for k, v in value.items() if not number(v)]
        if bad:
            raise DesignError(f"du_weight {bad[0]}={value[bad[0]]!r}: expected a non-negative "
                              "number")
        return np.array([float(value.get(name, 0.0)) for name in names])
    arr = np.atleast_1d(np.asarray(value, dtype=object))
    if arr.ndim != 1 or arr.size not in (1, m) or not all(number(v) for v in arr):
        raise DesignError(f"du_weight={value!r}: expected a non-negative number or {m} of "
                          "them (one per input)")
    return np.broadcast_to(arr.astype(float), (m,)).copy()


def du_cost(u: np.ndarray, u_prev: np.ndarray, weights: np.ndarray) -> float:
    """``J_Δu`` of inputs ``u`` (N, m) after ``u_prev`` (m,) with ``S = diag(weights)``."""
    d = np.diff(np.vstack([np.reshape(u_prev, (1, -1)), u]), axis=0)
    return float(np.vdot(d * weights, d))


def du_gradient(u: np.ndarray, u_prev: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``∇_u J_Δu`` (N, m): ``2 S (Δ_i − Δ_{i+1})`` with ``Δ_N = 0``."""
    d = np.diff(np.vstack([np.reshape(u_prev, (1, -1)), u]), axis=0)
    g = d.copy()
    g[:-1] -= d[1:]
    return 2.0 * weights * g


def du_hessian(N: int, weights: np.ndarray) -> np.ndarray:
    """``∇²_u J_Δu`` (N m × N m), constant: ``2 Dᵀ (I ⊗ S) D``."""
    m = weights.shape[0]
    D = np.eye(N * m) - np.eye(N * m, k=-m)
    return 2.0 * D.T @ (np.tile(weights, N)[:, None] * D)


class MoveRows:
    """The move limit of the FHOCP (issue 61, ``max_move``; docs: design/operating.md,
    ``eq:move-constraint``): ``|v_{i+1} − v_i| ≤ Δ`` element-wise along the chain
    ``v = (u_0 … u_{M−1}, u_end)`` of the free inputs in ``w`` ended by the input the plan
    settles at (the paper's ``ū``, a parameter; the tracking law's ``u_s``, a variable), so
    that the candidate of ``th:feasibility-stability`` (the plan shifted with ``u_end``
    appended) keeps every row. Linear rows appended after the law's own rows of ``g``; the
    first move ``u_0 − u_{−1}`` is a bound on ``u_0`` (the operator's terms,
    :class:`controllers.ocp.operator_terms.OperatorTerms`).

    Parameters
    ----------
    delta : (m,) array
        ``Δ`` per input (normalised, > 0).
    free : (M, m) int array
        The indices of ``u_0 … u_{M−1}`` in ``w``.
    end_w, end_p : (m,) int array or None
        The indices of ``u_end`` in ``w`` (the tracking law's ``u_s``) or in ``p`` (the
        paper's ``ū``); one of them.
    nw : int
        The size of ``w``.
    """

    def __init__(self, delta: np.ndarray, free: np.ndarray, end_w: np.ndarray | None,
                 end_p: np.ndarray | None, nw: int) -> None:
        self.delta = np.asarray(delta, dtype=float)
        self.free, self.end_w, self.end_p = np.asarray(free, dtype=int), end_w, end_p
        M, m = self.free.shape
        self.count = M * m
        J = np.zeros((self.count, nw))
        rows = np.arange(self.count).reshape(M, m)
        J[rows.ravel(), self.free.ravel()] = -1.0
        if M > 1:
            J[rows[:-1].ravel(), self.free[1:].ravel()] = 1.0
        if end_w is not None:
            J[rows[-1], end_w] = 1.0
        self.jacobian = J
        self.lower = -np.tile(self.delta, M)
        self.upper = np.tile(self.delta, M)

    def rows(self, wv: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """``v_{i+1} − v_i`` for ``i = 0 … M−1`` (M m,), stage after stage."""
        u = wv[self.free]
        end = wv[self.end_w] if self.end_w is not None else pv[self.end_p]
        return (np.vstack([u[1:], end[None]]) - u).ravel()

    def permutation(self) -> np.ndarray:
        """The warm start's shift of their multipliers by one stage (the last kept)."""
        M, m = self.free.shape
        blk = np.arange(M * m).reshape(M, m)
        return np.vstack([blk[1:], blk[-1:]]).ravel()


def move_limit(max_move: Any, inputs: Sequence[Any]) -> np.ndarray | None:
    """``Δ`` (normalised, per input) of the problem's inputs' ``max_move`` (problem units;
    an input without one: its box width, 2), ``None`` when no input declares one (no rows:
    the FHOCP as before)."""
    if max_move is None or all(v is None for v in max_move):
        return None
    return np.array([2.0 if v is None else float(v) / abs(float(c.scale))
                     for v, c in zip(max_move, inputs, strict=True)])
