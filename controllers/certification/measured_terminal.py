"""The uncertified mode's terminal weight for a model the theory gives none: ``eq:definition_s``
measured on the model's linearisation at its steady states.

``eq:definition_s`` bounds the cost to go from the last predicted state by
``s ‖x_N − x̄‖²_∞`` with ``s = n λ_max(Q) / (1 − ρ_s²) = n λ_max(Q) Σ_j ρ_s^{2j}``: the
model contracts ``V_s = ‖x_a − x_b‖∞`` by ``ρ_s`` per step (``lem:Vs``). With ``ν ≥ 1``
(``th:stability-bonassi`` fails) no ``ρ_s < 1`` is proved and ``s`` is infinite: the FHOCP
has no finite cost, and before this the model was not usable at all.

Measured instead (no guarantee, as the rest of the uncertified mode): near a steady state
``(x_s(u), u)`` a deviation evolves as ``δx_j = A_s^j δx_0`` (``A_s = ∂f/∂x`` there), and its
cost to go is ``Σ_j ‖δx_j‖²_Q = δx_0ᵀ P δx_0 ≤ n λ_max(P) ‖δx_0‖²_∞`` with ``P`` the solution of
the discrete Lyapunov equation ``P = A_sᵀ P A_s + Q``: the same bound as ``eq:definition_s``,
on the linearisation instead of the proved contraction. The measured terminal weight is the
largest ``n λ_max(P)`` over a grid of steady inputs across the input box; it is finite exactly
when every linearisation found on the grid is stable (spectral radius below 1), and
``ρ̂_s = (1 − n λ_max(Q) / ŝ)^{1/2}`` is the contraction rate ``eq:definition_s`` would need
to give it. A model whose linearisation is unstable somewhere on the grid has no finite cost
to go there either: it stays not usable, with that steady state named.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["GRID_POINTS", "MeasuredTerminal", "equivalent_contraction",
           "measured_terminal_weight"]

#: Steady inputs per input on the grid (``GRID_POINTS^m`` steady states, at most 3^5 = 243).
GRID_POINTS = 5


@dataclass(frozen=True)
class MeasuredTerminal:
    """The measured terminal weight (module docstring).

    Attributes
    ----------
    s : float
        ``ŝ = max n λ_max(P)`` over the grid; ``inf`` when a linearisation is unstable or no
        steady state was found.
    radius : float
        The largest spectral radius of ``A_s`` on the grid (``nan``: no steady state found).
    u : (m,) array or None
        The steady input (normalised) of the worst steady state: the largest radius when it
        is ``≥ 1``, else the largest ``n λ_max(P)``.
    """

    s: float
    radius: float
    u: np.ndarray | None

    def why_infinite(self, model: Any = None) -> str:
        """Why ``ŝ`` is infinite, the steady state in ``model``'s input names and units
        (normalised without a model); ``""`` when it is finite."""
        if math.isfinite(self.s):
            return ""
        if self.u is None:
            return "and the model has no steady state in the input box to measure one at"
        if model is None or getattr(model, "input_names", None) is None:
            where = "u = " + ", ".join(f"{v:.3g}" for v in self.u) + " (normalised)"
        else:
            phys = model.denormalize_u(np.asarray(self.u, dtype=float))
            units = getattr(model, "input_units", None) or [""] * len(phys)
            where = ", ".join(f"{name} = {v:.4g} {unit}".rstrip() for name, v, unit in zip(
                model.input_names, phys, units, strict=True))
        return (f"nor is the cost to go of the model's linearisation finite (spectral radius "
                f"{self.radius:.4g} >= 1 at its steady state for {where})")


def measured_terminal_weight(params: Mapping[str, np.ndarray], Q: np.ndarray,
                             grid_points: int = GRID_POINTS) -> MeasuredTerminal:
    """``ŝ`` of ``params``'s GRU with the stage weight ``Q`` over a grid of steady inputs
    (``grid_points`` per input, at most 243 steady states) in the normalised input box."""
    from scipy.linalg import solve_discrete_lyapunov

    from controllers.equilibrium import jacobians
    from controllers.ocp.steady_state import steady_state

    n, m = np.shape(params["W_z"])
    per_axis = max(2, min(int(grid_points), int(243 ** (1.0 / m))))
    axes = [np.linspace(-1.0, 1.0, per_axis)] * m
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    Q = np.asarray(Q, dtype=float)
    worst_s, worst_r, at_s, at_r = 0.0, -1.0, None, None
    x = np.zeros(n)
    for u in grid:
        with np.errstate(over="ignore"):   # a saturated gate: exp overflows to its limit
            xs, _, ok = steady_state(params, u, x)
        if not ok:
            continue
        x = xs
        A = jacobians(params, xs, u)[0]
        radius = float(np.max(np.abs(np.linalg.eigvals(A))))
        if radius > worst_r:
            worst_r, at_r = radius, u
        if radius >= 1.0:
            continue
        P = solve_discrete_lyapunov(A.T, Q)
        s = n * float(np.max(np.linalg.eigvalsh(0.5 * (P + P.T))))
        if s > worst_s:
            worst_s, at_s = s, u
    if at_r is None:
        return MeasuredTerminal(math.inf, math.nan, None)
    if worst_r >= 1.0 or not math.isfinite(worst_s):
        return MeasuredTerminal(math.inf, worst_r, np.array(at_r, dtype=float))
    return MeasuredTerminal(worst_s, worst_r, np.array(at_s, dtype=float))


def equivalent_contraction(n: int, Q: np.ndarray, s: float) -> float:
    """``ρ̂_s = (1 − n λ_max(Q) / s)^{1/2}``: the contraction rate ``eq:definition_s`` turns
    into the terminal weight ``s`` (``1`` for an infinite ``s``)."""
    if not math.isfinite(s):
        return 1.0
    lam = float(np.max(np.linalg.eigvalsh(np.asarray(Q, dtype=float))))
    return math.sqrt(max(0.0, 1.0 - n * lam / s))
