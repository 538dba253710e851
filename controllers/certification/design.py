"""Design arguments of the robust MPC, checked and defaulted: horizon, cost weights, gains.

Each check raises a one-line :class:`~controllers.errors.DesignError` naming the argument.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.errors import DesignError

__all__ = ["MAX_HORIZON", "gain", "horizon", "observer_gains", "scalars", "weight"]

#: Largest prediction horizon accepted (the FHOCP grows linearly with ``N``).
MAX_HORIZON = 1000


def horizon(N: Any) -> int:
    """The prediction horizon ``N`` as an int in ``1 … MAX_HORIZON`` (an integer-valued
    float is accepted)."""
    ok = isinstance(N, (int, np.integer)) and not isinstance(N, bool)
    if isinstance(N, (float, np.floating)) and math.isfinite(N) and float(N).is_integer():
        ok, N = True, int(N)
    if not ok:
        raise DesignError(f"horizon N must be an integer >= 1, got {N!r}")
    if not 1 <= N <= MAX_HORIZON:
        raise DesignError(f"horizon N must be >= 1 and <= {MAX_HORIZON}, got {N}")
    return int(N)


def weight(value: Any, name: str, size: int, default: float) -> np.ndarray:
    """Cost weight ``Q`` or ``R`` (``eq:optimization``): a symmetric positive definite
    ``(size, size)`` matrix; ``None`` gives ``default · I``."""
    if value is None:
        return default * np.eye(size)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise DesignError(f"cost weight {name} must be a {size}x{size} matrix of numbers, "
                         f"got {value!r}") from None
    if arr.shape != (size, size):
        raise DesignError(f"cost weight {name} must be a {size}x{size} matrix, got shape "
                         f"{arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise DesignError(f"cost weight {name} has non-finite entries")
    if not np.allclose(arr, arr.T) or np.min(np.linalg.eigvalsh(arr)) <= 0:
        raise DesignError(f"cost weight {name} must be symmetric positive definite")
    return arr


def gain(value: Any, name: str, n: int, p: int) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n, p):
        raise DesignError(f"observer gain {name} must have shape {(n, p)}, got {arr.shape}")
    return arr


def scalars(e_o0: Any, gain_scale: Any) -> float | None:
    """``ê_o,0`` and the observer-gain scale ``θ`` checked (non-negative numbers); ``θ`` as a
    float (``None``: not given)."""
    def bad(v: Any) -> bool:
        return (isinstance(v, bool) or not isinstance(v, (int, float, np.number))
                or not (math.isfinite(v) and v >= 0))

    if bad(e_o0):
        raise DesignError(f"e_o0 must be a non-negative number, got {e_o0!r}")
    if gain_scale is None:
        return None
    if bad(gain_scale):
        raise DesignError(f"gain scale must be a non-negative number, got {gain_scale!r}")
    return float(gain_scale)


def observer_gains(model: Any, bound: dict[str, np.ndarray], L_z: Any, L_r: Any,
                    gain_scale: float | None, n: int, p: int
                    ) -> tuple[np.ndarray, np.ndarray, float | None]:
    """The observer gains (``eq:observer``) of :func:`controllers.certification.certificates.
    compute_certificate`'s arguments (given, scaled by ``gain_scale``; else the LP gains of
    the model's bounds ``bound`` scaled; else the model file's), and the gain scale they
    have."""
    if (L_z is None) != (L_r is None):
        raise DesignError("give both observer gains L_z and L_r, or neither")
    if L_z is not None:
        L_z, L_r = gain(L_z, "L_z", n, p), gain(L_r, "L_r", n, p)
        if gain_scale is not None:
            L_z, L_r = gain_scale * L_z, gain_scale * L_r
        return L_z, L_r, gain_scale
    if gain_scale is not None or getattr(model, "L_z", None) is None:
        theta = 1.0 if gain_scale is None else float(gain_scale)
        from controllers.certification.observer_gains import observer_gains_lp

        Lz_lp, Lr_lp = observer_gains_lp(bound)
        return theta * Lz_lp, theta * Lr_lp, theta
    return gain(model.L_z, "L_z", n, p), gain(model.L_r, "L_r", n, p), gain_scale
