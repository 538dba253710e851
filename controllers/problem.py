"""The control problem: which signals a controller manipulates and measures, and their bounds.

Shared by every controller of the four-tank benchmark (the PI baseline and the robust MPC),
so that constraints are declared once. Bounds are in physical units.
"""

from __future__ import annotations

from dataclasses import dataclass


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
