"""Observer-gain design: the LP gains minimising ``ν_o`` and the gain scale ``θ``.

The gains of ``eq:observer`` that minimise ``ν_o`` (``lem:Vo``; one linear program per row,
paper section V) make ``ρ_o`` small but ``κ`` and ``L_max`` large, and with them ``w̄``,
``ē_∞``, ``a_i``, ``b_i``: on a real model ``α`` is then negative everywhere (the prototype's
finding). The design lever is therefore ``L = θ·L_LP`` with the largest ``θ ∈ [0, 1]`` for
which every hypothesis of ``th:feasibility-stability`` holds at the set-points of interest
(:func:`choose_gain_scale`; ``θ = 0`` is the open-loop observer, ``rem:observer-gains``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from controllers.certification.bounds import check_gates
from controllers.certification.certificates import Certificate, compute_certificate
from controllers.certification.observer_gains import observer_gains_lp

__all__ = ["choose_gain_scale", "default_setpoints", "observer_gains_lp"]

#: Where in each output's box the default set-points lie (fractions of its width).
GRID_FRACTIONS = (0.25, 0.5, 0.75)
#: Most default set-points: beyond, a star (the middle, ±25 % along each output) replaces
#: the full grid.
MAX_GRID_POINTS = 81


def default_setpoints(problem: Any) -> list[tuple[float, ...]]:
    """Set-points (physical units) at which the gain scale is chosen when none are given
    (``cosim certify --auto-gain-scale``, and the robust MPC for a model file without
    gains): the grid of :data:`GRID_FRACTIONS` of each output's box (3^p points; for the
    four-tank's [0, 2] m boxes, {0.5, 1.0, 1.5}²), or a star of 2p + 1 points when the grid
    would exceed :data:`MAX_GRID_POINTS`."""
    import itertools

    boxes = [(c.min, c.max) for c in problem.outputs]
    levels = [[lo + f * (hi - lo) for f in GRID_FRACTIONS] for lo, hi in boxes]
    if len(GRID_FRACTIONS) ** len(boxes) <= MAX_GRID_POINTS:
        return [tuple(pt) for pt in itertools.product(*levels)]
    mid = [lv[1] for lv in levels]
    points = [tuple(mid)]
    for j, lv in enumerate(levels):
        for k in (0, 2):
            pt = list(mid)
            pt[j] = lv[k]
            points.append(tuple(pt))
    return points


# --------------------------------------------------------------------------------------
# Design lever: the observer-gain scale
# --------------------------------------------------------------------------------------
def choose_gain_scale(model: Any, setpoints_norm: Iterable[Sequence[float]], *,
                      N: int, Q: np.ndarray | None = None, R: np.ndarray | None = None,
                      e_o0: float = 0.02, w_y_bar: float | None = None,
                      L_z: np.ndarray | None = None, L_r: np.ndarray | None = None,
                      grid: Sequence[float] | None = None, iterations: int = 40,
                      **kwargs: Any) -> tuple[float | None, Certificate]:
    """Largest ``θ ∈ [0, 1]`` such that the gains ``θ·L`` pass every hypothesis.

    The prototype found ``α < 0`` with the LP-optimal gains: large gains shrink ``ρ_o`` but
    grow ``κ`` (hence ``w̄``, ``ē_∞``, ``b_i``) and ``L_max`` (hence ``a_i``). This searches
    ``θ`` for ``L = θ·L`` (``L`` = the LP gains of :func:`observer_gains_lp` unless given)
    such that ν < 1, ν_o < 1, Assumption 1 (``ass:setpoint``), ``α > 0`` (``eq:def-alpha``)
    and ``eq:condition-recursive-feasibility`` hold at every set-point. The conditions need
    not be monotone in ``θ``: a grid (1, then 4 points per decade down to 1e-6, then 0) finds
    the largest passing grid value, refined by bisection towards the next larger grid value.

    Returns
    -------
    theta : float or None
        The scale, or ``None`` when even ``θ = 0`` (the open-loop observer, ``rem:observer-
        gains``) fails.
    certificate : Certificate
        At ``theta`` (at ``θ = 0`` when ``theta`` is None).
    """
    setpoints = [np.asarray(y, dtype=float) for y in setpoints_norm]
    check_gates({k: np.asarray(v, dtype=float) for k, v in model.params.items()},
                getattr(model, "source", None))
    if L_z is None or L_r is None:
        L_z, L_r = observer_gains_lp(model.params)
    if grid is None:
        grid = [1.0, *[10 ** (-k / 4) for k in range(1, 25)], 0.0]

    def cert(theta: float) -> Certificate:
        return compute_certificate(model, N=N, Q=Q, R=R, e_o0=e_o0, w_y_bar=w_y_bar,
                                   L_z=theta * L_z, L_r=theta * L_r, **kwargs)

    def passes(c: Certificate) -> bool:
        return not c.failures() and all(c.ok(y) for y in setpoints)

    previous = None
    for theta in grid:
        c = cert(theta)
        if passes(c):
            if previous is not None:  # refine between theta (pass) and previous (fail)
                lo, hi = theta, previous
                for _ in range(iterations):
                    mid = 0.5 * (lo + hi)
                    cm = cert(mid)
                    if passes(cm):
                        lo, c = mid, cm
                    else:
                        hi = mid
                theta = lo
            c.gain_scale = theta
            return theta, c
        previous = theta
    c = cert(0.0)
    c.gain_scale = 0.0
    return None, c
