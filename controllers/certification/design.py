"""Design arguments of the robust MPC, checked and defaulted: horizon, cost weights, gains.

Each check raises a one-line :class:`~controllers.errors.DesignError` naming the argument.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.errors import DesignError

__all__ = ["MAX_HORIZON", "gain", "horizon", "weight"]

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
