"""The tracking law's hypotheses, computed at run time (docs: design/tracking.md, H3-H6).

What the paper's certificate (:mod:`controllers.certification.certificates`) checks stays; the
tracking law (:mod:`controllers.laws.tracking.reference`) adds, once per model and design:

- (H3) the weights: ``Q ≻ 0``, ``R ≻ 0``, ``S ⪰ 0`` (the Δu weights), ``T ≻ 0`` (the offset
  weights), and the terminal weight ``s`` of ``eq:definition_s`` (the certificate's);
- (H4) ``eq:condition-recursive-feasibility`` at the one terminal radius:
  ``α_c > 0`` and ``α_c ≥ α_min(N)``;
- (H5) the admissible steady outputs ``Y_s = {y : L y ≤ h − ẽ_o a_N − b_N − w_L − α_c c_s}``
  are not empty (a linear program);
- (H6), reported rather than required: on a grid over the input box, the steady-state gain
  ``G(u) = U_o (I − A_s)^{-1} B_s`` at the steady states whose outputs lie in ``Y_s``: its
  smallest singular value (``> 0``: the steady outputs there are parametrised by ``u_s``, the
  closest admissible steady state is locally unique), and how many grid points are
  admissible;
- the disturbance filter's ``0 < β ≤ 1``.

:func:`tracking_hypotheses` returns them as a dictionary (what the controller's summary
reports); :func:`failures` names the ones that fail (a design error).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.gru import output
from controllers.ocp.steady_state import steady_state

__all__ = ["failures", "tracking_hypotheses"]


def _ys_nonempty(L: np.ndarray, rhs: np.ndarray) -> tuple[bool, np.ndarray | None]:
    """Whether ``{y : L y ≤ rhs}`` has a point (with its Chebyshev centre when it has)."""
    from scipy.optimize import linprog

    p = L.shape[1]
    rhs = np.asarray(rhs, dtype=float)
    if np.any(np.isnan(rhs) | (rhs == -np.inf)):   # a row tightened past any bound: empty
        return False, None
    keep = np.isfinite(rhs)   # a row loosened past any bound constrains nothing
    L, rhs = L[keep], rhs[keep]
    if not rhs.size:
        return True, np.zeros(p)
    norms = np.linalg.norm(L, axis=1)
    # max r s.t. L y + ‖L_j‖ r ≤ rhs: the Chebyshev ball (r ≥ 0 when non-empty)
    res = linprog(np.r_[np.zeros(p), -1.0], A_ub=np.c_[L, norms], b_ub=rhs,
                  bounds=[(None, None)] * p + [(None, 1e3)], method="highs")
    if res.status != 0 or -res.fun < 0:
        return False, None
    return True, res.x[:p]


def tracking_hypotheses(fhocp: Any, cert: Any, beta: float,
                        grid_points: int = 11) -> dict[str, Any]:
    """The hypotheses of the FHOCP ``fhocp`` with the tracking law's reference (a
    :class:`~controllers.laws.tracking.reference.ArtificialSteadyState`) designed from
    ``cert``, with the disturbance filter's ``beta`` (module docstring)."""
    eig = np.linalg.eigvalsh
    ass = fhocp.reference   # the artificial steady state
    a_min = float(cert.alpha_min())
    nonempty, centre = _ys_nonempty(fhocp.L, ass.ys_bounds)
    P = fhocp.params
    m = fhocp.m
    axes = [np.linspace(-1.0, 1.0, grid_points)] * m
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    sv, admissible = [], 0
    x = np.zeros(fhocp.n)
    for u in grid:
        xs, Xs, ok = steady_state(P, u, x)
        if not ok:
            continue
        x = xs
        if np.all(fhocp.L @ output(P, xs) <= ass.ys_bounds):
            admissible += 1
            G = P["U_o"] @ Xs
            sv.append(float(np.linalg.svd(G, compute_uv=False)[-1]))
    return {
        "Q_min_eigenvalue": float(eig(fhocp.Q)[0]),
        "R_min_eigenvalue": float(eig(fhocp.R)[0]),
        "du_weight_min": float(np.min(fhocp.du_weight)),
        "offset_weight_min": float(np.min(ass.offset_weight)),
        "s": float(fhocp.s),
        "alpha_c": float(ass.alpha_c),
        "alpha_min": a_min,
        "recursive_feasibility": bool(ass.alpha_c > 0 and a_min <= ass.alpha_c),
        "Ys_nonempty": bool(nonempty),
        "Ys_centre": None if centre is None else [float(v) for v in centre],
        "grid_points": int(grid.shape[0]),
        "grid_points_admissible": int(admissible),
        "steady_gain_min_singular_value": float(min(sv)) if sv else None,
        "offset_filter": float(beta),
    }


def failures(h: dict[str, Any]) -> list[str]:
    """The hypotheses in ``h`` (:func:`tracking_hypotheses`) that fail, in words."""
    out = []
    if not (h["Q_min_eigenvalue"] > 0 and h["R_min_eigenvalue"] > 0):
        out.append("Q and R must be positive definite")
    if h["du_weight_min"] < 0 or not h["offset_weight_min"] > 0:
        out.append("du_weight must be >= 0 and offset_weight > 0")
    if not h["recursive_feasibility"]:
        out.append(f"alpha_c = {h['alpha_c']:g} fails eq:condition-recursive-feasibility "
                   f"(alpha_min(N) = {h['alpha_min']:g})")
    if not h["Ys_nonempty"]:
        out.append(f"no admissible steady output: Y_s is empty for alpha_c = {h['alpha_c']:g} "
                   "(a smaller alpha_c, or a longer horizon)")
    if not 0 < h["offset_filter"] <= 1:
        out.append(f"offset_filter = {h['offset_filter']:g} must be in (0, 1]")
    return out
