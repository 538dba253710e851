"""The artificial steady state of the tracking FHOCP: ``x_s(u_s)`` and ``∂x_s/∂u_s``.

For a δISS GRU (``th:stability-bonassi``, ν < 1) the map ``f(·, u_s)`` contracts, so each input
``u_s`` has exactly one steady state ``x_s = f(x_s, u_s)`` (``lem:Vs``), and by the implicit
function theorem ``X_s = ∂x_s/∂u_s = (I − A_s)^{-1} B_s`` with ``[A_s B_s]`` the Jacobian of
``eq:gru`` at ``(x_s, u_s)``. Newton's method from a start ``x_0`` (the previous step's
``x_s``) finds it in a few iterations. The compiled kernel runs the same iteration
(``controllers/kernel/steady_state.c``), with the same stopping rule, so both agree to
rounding.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from controllers.equilibrium import jacobians
from controllers.gru import step

__all__ = ["XS_MAX_ITER", "XS_TOL", "steady_state"]

#: Newton's iteration cap and step tolerance (relative to ``max(1, ‖x‖∞)``); as the kernel.
XS_MAX_ITER = 50
XS_TOL = 1e-13


def steady_state(params: Mapping[str, np.ndarray], u_s: np.ndarray,
                 x0: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(x_s, X_s, converged)``: the steady state of ``u_s`` by Newton from ``x0`` and its
    derivative ``X_s`` (n×m); both NaN when Newton did not converge (a NaN cost makes the
    SQP's line search step back)."""
    u_s = np.asarray(u_s, dtype=float)
    x = np.array(x0, dtype=float)
    n = x.shape[0]
    eye = np.eye(n)
    ok = False
    for _ in range(XS_MAX_ITER):
        F = step(params, x, u_s) - x
        f_x, _ = jacobians(params, x, u_s)
        try:
            d = np.linalg.solve(eye - f_x, F)
        except np.linalg.LinAlgError:
            break
        x = x + d
        if not np.all(np.isfinite(d)):
            break
        if np.max(np.abs(d)) <= XS_TOL * max(1.0, float(np.max(np.abs(x)))):
            ok = True
            break
    if ok:
        f_x, f_u = jacobians(params, x, u_s)
        try:
            return x, np.linalg.solve(eye - f_x, f_u), True
        except np.linalg.LinAlgError:
            pass
    m = u_s.shape[0]
    return np.full(n, np.nan), np.full((n, m), np.nan), False
