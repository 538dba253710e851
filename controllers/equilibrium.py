"""Equilibria of the GRU model: ``x̄ = f(x̄, ū)``, ``U_o x̄ + b_o = ȳ``, ``‖ū‖∞ ≤ 1``.

The FHOCP (``eq:optimization``) penalises ``x − x̄`` and ``u − ū`` where ``(x̄, ū)`` is the
model equilibrium whose output is the set-point ``ȳ`` (paper section IV-B); the observer
starts at the equilibrium for the first measured output (paper section V).

Method (deterministic, numpy + scipy): for a fixed ``u`` the state equilibrium ``x(u)`` is
the unique fixed point of the contraction ``f(·, u)`` when ``ν < 1`` (``lem:Vs``); it is
found by Newton's method on ``f(x, u) − x = 0``, with fixed-point iterations as a fallback.
The output equation ``U_o x(u) + b_o = ȳ`` is then solved for ``u`` in the box
``[−1, 1]^m`` by bounded least squares (scipy ``least_squares``, exact Jacobian from the
implicit-function theorem ``dx/du = (I − f_x)^{-1} f_u``) from a fixed set of starting
points. ``‖x̄‖∞ < 1`` holds automatically: ``x̄ = h(x̄, ū)`` with ``|h| < 1``.

Any numbers of inputs ``m`` and outputs ``p``: with ``m > p`` many inputs hold one output
(the least squares returns one of them, the same every time); with ``p > m`` the equilibrium
outputs form an ``m``-dimensional surface in the ``p``-dimensional output space and a
set-point off it is unreachable: :func:`equilibrium` names the closest reachable output.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from controllers.errors import UnreachableSetpoint
from controllers.gru import NUMPY_OPS, gates, step

__all__ = ["EQ_TOL", "NEWTON_MAX_ITER", "REACH_TOL", "box_boundary", "describe", "equilibrium",
           "equilibrium_for_output", "equilibrium_newton", "equilibrium_output", "jacobians",
           "reachable_boundary", "state_equilibrium"]

#: Residual (∞-norm, normalised units) below which a set-point counts as reached.
REACH_TOL = 1e-8


def _params(model_or_params: Any) -> dict[str, np.ndarray]:
    p = getattr(model_or_params, "params", model_or_params)
    return {k: np.asarray(v, dtype=float) for k, v in p.items()}


def jacobians(params: Mapping[str, np.ndarray], x: np.ndarray,
              u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact Jacobians ``(∂f/∂x, ∂f/∂u)`` of the GRU state update ``eq:gru`` at ``(x, u)``."""
    z, r, h = gates(params, x, u, NUMPY_OPS)
    dz = (z * (1 - z))[:, None]
    dr = (r * (1 - r))[:, None]
    dh = (1 - h**2)[:, None]
    z_x, z_u = dz * params["U_z"], dz * params["W_z"]
    r_x, r_u = dr * params["U_r"], dr * params["W_r"]
    rx_x = np.diag(r) + x[:, None] * r_x          # ∂(r∘x)/∂x
    rx_u = x[:, None] * r_u                        # ∂(r∘x)/∂u
    h_x = dh * (params["U_h"] @ rx_x)
    h_u = dh * (params["W_h"] + params["U_h"] @ rx_u)
    f_x = np.diag(z) + (x - h)[:, None] * z_x + (1 - z)[:, None] * h_x
    f_u = (x - h)[:, None] * z_u + (1 - z)[:, None] * h_u
    return f_x, f_u


def state_equilibrium(params: Mapping[str, np.ndarray], u: np.ndarray,
                      x0: np.ndarray | None = None, tol: float = 1e-13,
                      max_iter: int = 100) -> np.ndarray:
    """The state ``x`` with ``x = f(x, u)`` for a fixed input ``u`` (Newton, then iteration).

    Unique in ``‖x‖∞ ≤ 1`` when the model is δISS (``lem:Vs``: ``f(·, u)`` contracts).
    """
    p = params
    n = p["U_z"].shape[0]
    u = np.asarray(u, dtype=float)
    x = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    eye = np.eye(n)
    for _ in range(max_iter):
        F = step(p, x, u) - x
        if np.max(np.abs(F)) < tol:
            return x
        f_x, _ = jacobians(p, x, u)
        try:
            dx = np.linalg.solve(f_x - eye, -F)
        except np.linalg.LinAlgError:
            break
        # damped step: stay in the box and reduce the residual
        t = 1.0
        while t > 1e-4:
            xn = np.clip(x + t * dx, -1.0, 1.0)
            if np.max(np.abs(step(p, xn, u) - xn)) < np.max(np.abs(F)):
                break
            t *= 0.5
        else:
            break
        x = xn
    # fallback: plain fixed-point iteration (converges when f(·, u) contracts)
    for _ in range(20000):
        xn = step(p, x, u)
        if np.max(np.abs(xn - x)) < tol:
            return xn
        x = xn
    return x


def _solve(params: dict[str, np.ndarray], y: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                   float]:
    """Bounded least squares for ``u``; returns ``(x, u, residual ∞-norm)`` of the best
    start."""
    from scipy.optimize import least_squares

    n, m = params["W_z"].shape
    Uo, bo = params["U_o"], params["b_o"]
    eye = np.eye(n)
    cache = {"x": np.zeros(n)}

    def x_of(u: np.ndarray) -> np.ndarray:
        x = state_equilibrium(params, u, cache["x"])
        cache["x"] = x
        return x

    def res(u: np.ndarray) -> np.ndarray:
        return Uo @ x_of(u) + bo - y

    def jac(u: np.ndarray) -> np.ndarray:
        x = x_of(u)
        f_x, f_u = jacobians(params, x, u)
        return Uo @ np.linalg.solve(eye - f_x, f_u)

    starts = [np.zeros(m)]
    for s in (0.5, -0.5):
        starts.append(np.full(m, s))
    for i in range(m):
        for s in (0.5, -0.5):
            v = np.zeros(m)
            v[i] = s
            starts.append(v)
    best: tuple[np.ndarray, np.ndarray, float] | None = None
    agree = 0
    for u0 in starts:
        cache["x"] = np.zeros(n)
        sol = least_squares(res, u0, jac=jac, bounds=(-np.ones(m), np.ones(m)),
                            method="trf", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=100)
        u = np.clip(sol.x, -1.0, 1.0)
        x = state_equilibrium(params, u, None)
        err = float(np.max(np.abs(Uo @ x + bo - y)))
        if best is not None and np.max(np.abs(u - best[1])) < 1e-7:
            agree += 1  # another start found the same point
        if best is None or err < best[2] - 1e-15:
            best = (x, u, err)
        if err < REACH_TOL * 1e-3 or agree >= 2:
            break
    assert best is not None
    return best


def describe(model: Any, y: np.ndarray) -> str:
    """A set-point for messages: ``h1=0.9 m, h2=1.2 m`` with a model (physical units), else
    the normalised vector."""
    names = getattr(model, "output_names", None)
    if names is not None and hasattr(model, "denormalize_y"):
        phys = model.denormalize_y(y)
        units = getattr(model, "output_units", [""] * len(phys))
        return ", ".join(f"{nm}={v:.4g}{(' ' + un) if un else ''}"
                         for nm, v, un in zip(names, phys, units, strict=True))
    return "[" + ", ".join(f"{v:.6g}" for v in y) + "] (normalised)"


def equilibrium(model_or_params: Any, y_bar_norm: Sequence[float],
                kernel: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Model equilibrium ``(x̄, ū)`` with output ``ȳ`` (normalised) and ``‖ū‖∞ ≤ 1``.

    Solves ``x̄ = f(x̄, ū)``, ``U_o x̄ + b_o = ȳ`` (``eq:gru``; the reference of the FHOCP
    ``eq:optimization``).

    Parameters
    ----------
    model_or_params : GRUModel or mapping of arrays
        With a :class:`GRUModel`, error messages are in physical units.
    y_bar_norm : (p,) array
        Set-point in normalised units.
    kernel : optional
        A compiled kernel's workspace of the same model: its compiled search
        (:func:`equilibrium_for_output`'s, the exported controller's) is used.

    Raises
    ------
    UnreachableSetpoint
        (a :class:`~controllers.errors.SetpointError`) when no ``‖ū‖∞ ≤ 1`` reaches
        ``ȳ``; the message names the set-point and the closest reachable equilibrium output.
    """
    params = _params(model_or_params)
    y = np.asarray(y_bar_norm, dtype=float).reshape(-1)
    if kernel is not None and kernel.has_equilibrium:
        x, u, reached = kernel.equilibrium(y)
        err = 0.0 if reached else np.inf
    else:
        x, u, err = _solve(params, y)
    if err > REACH_TOL:
        reach = params["U_o"] @ x + params["b_o"]
        m, p = params["W_z"].shape[1], params["U_o"].shape[0]
        why = (f" ({p} outputs, {m} input{'s' if m > 1 else ''}: only the model's "
               f"{m}-dimensional surface of equilibrium outputs is reachable)" if p > m else "")
        raise UnreachableSetpoint(
            f"set-point {describe(model_or_params, y)} is not reachable with inputs inside "
            f"the saturation box (‖u‖∞ ≤ 1){why}; the closest reachable equilibrium output is "
            f"{describe(model_or_params, reach)}")
    return x, u


def equilibrium_for_output(model_or_params: Any, y_norm: Sequence[float],
                           kernel: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Equilibrium ``(x, u)`` whose output is closest to ``y`` (normalised), never raising.

    Used for the observer's initial state ``x̂_0`` (paper section V: the equilibrium for the
    first measured output); when ``y`` is not reachable the closest reachable equilibrium
    (least squares over ``‖u‖∞ ≤ 1``) is returned. ``kernel``: a compiled kernel's workspace
    of the same model; a tracking FHOCP's has the same search compiled
    (:meth:`controllers.kernel.kernel_lib.Workspace.equilibrium`, the exported controller's),
    which is then used.
    """
    if kernel is not None and kernel.has_equilibrium:
        x, u, _ = kernel.equilibrium(np.asarray(y_norm, dtype=float).reshape(-1))
        return x, u
    params = _params(model_or_params)
    x, u, _ = _solve(params, np.asarray(y_norm, dtype=float).reshape(-1))
    return x, u


#: Residual ∞-norm accepted for an equilibrium from Newton's method (normalised units), and
#: its iteration cap (the compiled kernel's ``eq_newton`` and the exported governor's too).
EQ_TOL = 1e-11
NEWTON_MAX_ITER = 20


def equilibrium_newton(params: Mapping[str, np.ndarray], y: np.ndarray, x0: np.ndarray,
                       u0: np.ndarray, max_iter: int = NEWTON_MAX_ITER,
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """Equilibrium ``x = f(x, u)``, ``U_o x + b_o = y`` (``eq:gru``) by Newton's method from
    ``(x0, u0)``; ``None`` when it does not converge or leaves ``‖u‖∞ ≤ 1``.

    The Newton matrix is ``(n + p) × (n + m)``: square when ``m = p`` (a linear solve, as the
    compiled kernel's ``eq_newton``); otherwise each step is its least-squares solution
    (``numpy.linalg.lstsq``): the minimum-norm step when ``m > p`` (the equilibrium closest
    to ``(x0, u0)`` along the continuation; the kernel's ``eq_newton`` takes the same step by
    the normal equations), Gauss–Newton when ``p > m`` (it reaches a zero
    residual only for a set-point on the surface of equilibrium outputs, else ``None``).
    """
    n = x0.shape[0]
    m = u0.shape[0]
    Uo, bo = params["U_o"], params["b_o"]
    square = Uo.shape[0] == m
    x, u = np.array(x0, dtype=float), np.array(u0, dtype=float)
    K = np.zeros((n + Uo.shape[0], n + m))
    eye = np.eye(n)
    for _ in range(max_iter):
        F = np.concatenate([step(params, x, u) - x, Uo @ x + bo - y])
        if np.max(np.abs(F)) < EQ_TOL:
            return (x, u) if np.max(np.abs(u)) <= 1.0 else None
        f_x, f_u = jacobians(params, x, u)
        K[:n, :n] = f_x - eye
        K[:n, n:] = f_u
        K[n:, :n] = Uo
        try:
            d = (np.linalg.solve(K, -F) if square
                 else np.linalg.lstsq(K, -F, rcond=None)[0])
        except np.linalg.LinAlgError:
            return None
        x = x + d[:n]
        u = u + d[n:]
    return None


def equilibrium_output(params: Mapping[str, np.ndarray], u: np.ndarray,
                       x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)``: the state equilibrium ``x = f(x, u)`` for a fixed input (``eq:gru``) and
    its output ``y = U_o x + b_o`` (normalised), from ``x0``."""
    p = _params(params)
    x = state_equilibrium(p, np.asarray(u, dtype=float), x0)
    return x, p["U_o"] @ x + p["b_o"]


def box_boundary(m: int, points: int = 60) -> np.ndarray:
    """Inputs on the edges of the box ``‖u‖∞ ≤ 1`` of ``m`` inputs, normalised:

    - ``m = 1``: the segment ``u`` from −1 to 1 (``points`` values; its image is the whole
      reachable set, a curve);
    - ``m = 2``: the square's four sides as one closed path (``4 points`` values: bottom,
      right, top, left);
    - ``m ≥ 3``: the ``m 2^(m−1)`` edges of the cube (one coordinate free, the others ±1),
      ``points`` values each, edge after edge (no closed path). For a map whose 2-faces map
      with full rank, the edge of the image of the box in a plane is the image of these
      edges.
    """
    import itertools

    s = np.linspace(-1.0, 1.0, points)
    if m == 1:
        return s[:, None]
    if m == 2:
        edges = [np.c_[s, -np.ones_like(s)], np.c_[np.ones_like(s), s],
                 np.c_[s[::-1], np.ones_like(s)], np.c_[-np.ones_like(s), s[::-1]]]
        return np.vstack(edges)
    out = []
    for i in range(m):
        for corner in itertools.product((-1.0, 1.0), repeat=m - 1):
            seg = np.tile(np.insert(np.array(corner), i, 0.0), (points, 1))
            seg[:, i] = s
            out.append(seg)
    return np.vstack(out)


def reachable_boundary(model: Any, points: int = 60) -> np.ndarray:
    """Physical outputs ``(k, p)`` of the model equilibria for the inputs of
    :func:`box_boundary` (``‖u‖∞ = 1``): the edge of the set of reachable set-points.

    - ``m = 1``: the outputs along ``u ∈ [−1, 1]``, an open curve (with ``p ≥ 2`` it is the
      whole reachable set; with ``p = 1`` its extremes bound the reachable interval);
    - ``m = 2``: a closed path (the edge of a region when ``p = 2``);
    - ``m ≥ 3``: with ``p = 2``, a closed path: the outline of the outputs along the cube's
      edges seen from the equilibrium output at ``u = 0`` (the farthest point in each of
      ``2 points`` angular sectors, in normalised units: the edge for a region star-shaped
      about that point); with ``p ≠ 2`` the outputs along the edges, edge after edge.

    The equilibria are continued from one input to the next (:func:`state_equilibrium`).
    """
    params = _params(model)
    m, p = params["W_z"].shape[1], params["U_o"].shape[0]
    ys, x = [], None
    for u in box_boundary(m, points):
        x = state_equilibrium(params, u, x)
        ys.append(params["U_o"] @ x + params["b_o"])
    y = np.array(ys)
    if m >= 3 and p == 2:
        _, centre = equilibrium_output(params, np.zeros(m))
        d = y - centre
        sectors = 2 * points
        k = np.minimum((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * sectors,
                       sectors - 1).astype(int)
        r = np.hypot(d[:, 0], d[:, 1])
        edge = [y[np.flatnonzero(k == b)[np.argmax(r[k == b])]] for b in range(sectors)
                if np.any(k == b)]
        y = np.array([*edge, edge[0]])
    return np.array([model.denormalize_y(v) for v in y])
