"""The control problem: which signals a controller manipulates and measures, and their bounds.

Shared by every controller of the four-tank benchmark (the PI baseline and the robust MPC),
so that constraints are declared once. Bounds are in physical units.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.errors import DesignError

__all__ = ["FOURTANK", "ControlProblem", "constraint_names", "output_constraints"]


@dataclass(frozen=True)
class ControlProblem:
    """Manipulated inputs and controlled outputs with their box constraints.

    Attributes
    ----------
    inputs : tuple of str
        Manipulated plant inputs (controller outputs), e.g. ``("qa", "qb")``.
    input_bounds : tuple of (float, float)
        ``(min, max)`` per input (``eq:input-constraint`` after normalisation).
    input_units : tuple of str
    outputs : tuple of str
        Measured, controlled plant outputs (controller inputs), e.g. ``("h1", "h2")``.
    output_bounds : tuple of (float, float)
        ``(min, max)`` per output: the polytope ``L y ≤ h`` of ``eq:output-constraint``.
    output_units : tuple of str
    Ts : float
        Controller sample time [s].
    """

    inputs: tuple[str, ...]
    input_bounds: tuple[tuple[float, float], ...]
    input_units: tuple[str, ...]
    outputs: tuple[str, ...]
    output_bounds: tuple[tuple[float, float], ...]
    output_units: tuple[str, ...]
    Ts: float

    def bounds(self) -> dict[str, tuple[float, float]]:
        """All bounds by signal name (inputs and outputs)."""
        return dict(zip(self.inputs + self.outputs, self.input_bounds + self.output_bounds,
                        strict=True))


#: The four-tank benchmark of the paper's section V (Alvarado et al. 2011).
FOURTANK = ControlProblem(
    inputs=("qa", "qb"),
    input_bounds=((0.0, 9.05e-4), (0.0, 11.1e-4)),
    input_units=("m3/s", "m3/s"),
    outputs=("h1", "h2"),
    output_bounds=((0.0, 2.0), (0.0, 2.0)),
    output_units=("m", "m"),
    Ts=25.0,
)


def output_constraints(model: Any, problem: ControlProblem = FOURTANK) -> tuple[np.ndarray,
                                                                               np.ndarray]:
    """``(L, h)`` of ``eq:output-constraint`` (``L y ≤ h``) in the model's normalised units.

    For each model output ``j`` (matched by name with ``problem.outputs``) two rows:
    ``+y_j ≤ (max − offset)/scale`` and ``−y_j ≤ −(min − offset)/scale``; a negative scale
    swaps the two bounds.
    """
    names = list(model.output_names)
    rows, rhs = [], []
    bounds = dict(zip(problem.outputs, problem.output_bounds, strict=True))
    for j, name in enumerate(names):
        if name not in bounds:
            raise DesignError(f"model output {name!r} has no bounds in the control problem "
                             f"(outputs {', '.join(problem.outputs)})")
        lo, hi = bounds[name]
        off, sc = float(model.y_offset[j]), float(model.y_scale[j])
        nlo, nhi = sorted(((lo - off) / sc, (hi - off) / sc))
        e = np.zeros(len(names))
        e[j] = 1.0
        rows += [e, -e]
        rhs += [nhi, -nlo]
    return np.array(rows), np.array(rhs)


def constraint_names(model: Any, problem: ControlProblem = FOURTANK) -> list[str]:
    """Readable names of the rows of :func:`output_constraints` (e.g. ``h1 <= 2 m``)."""
    bounds = dict(zip(problem.outputs, problem.output_bounds, strict=True))
    units = dict(zip(problem.outputs, problem.output_units, strict=True))
    names = []
    for j, name in enumerate(model.output_names):
        lo, hi = bounds[name]
        if model.y_scale[j] < 0:
            lo, hi = hi, lo
        names += [f"{name} <= {hi:g} {units[name]}", f"{name} >= {lo:g} {units[name]}"]
    return names
