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

__all__ = ["du_cost", "du_gradient", "du_hessian", "du_weights"]


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
