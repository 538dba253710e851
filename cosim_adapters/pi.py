"""Decentralised PI baseline for the four-tank benchmark (the controller the MPC is compared to).

Two independent discrete PI loops sampled at ``Ts``, each with input saturation to the
problem's bounds and back-calculation anti-windup (Åström & Hägglund)::

    e_k   = r_k − y_k
    v_k   = I_k + K e_k                       (unsaturated)
    u_k   = sat(v_k)                          (held over [t_k, t_k + Ts))
    I_k+1 = I_k + K Ts / Ti · e_k + Ts / Tt · (u_k − v_k)

Pairing. With the paper's parameters (γ_a = 0.3, γ_b = 0.4, γ_a + γ_b < 1) the plant is in
the non-minimum-phase configuration: most of ``qa`` reaches tank 2 (through tank 4) and most
of ``qb`` reaches tank 1. The steady-state relative gain of the diagonal pairing is
``λ = γ_a γ_b / (γ_a + γ_b − 1) = −0.4 < 0``, so decentralised integral control with the
pairing h1–qa, h2–qb is unstable unless one loop is given the "wrong" sign (Johansson 2000),
and it tracks poorly. The default pairing is therefore the one with ``λ = 1.4``: h1 with qb,
h2 with qa. ``pairing="diagonal"`` selects h1–qa, h2–qb (with the tuning found for it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from controllers.problem import FOURTANK, ControlProblem
from cosim.component import Component, Signal
from cosim.errors import CosimError

__all__ = ["PAIRINGS", "PIController", "PILoop"]


@dataclass(frozen=True)
class PILoop:
    """One loop: output ``y`` controlled by input ``u``; gain ``K`` [u-unit per y-unit]."""

    y: str
    u: str
    K: float
    Ti: float
    Tt: float


#: Tunings found by simulating the plant's ODE over a set-point sequence (IAE, smooth input).
PAIRINGS: dict[str, tuple[PILoop, PILoop]] = {
    "cross": (PILoop("h1", "qb", 1.0e-3, 400.0, 400.0),
              PILoop("h2", "qa", 5.0e-4, 400.0, 400.0)),
    # Negative-RGA pairing: needs a negative gain on one loop; kept for comparison only.
    "diagonal": (PILoop("h1", "qa", -5.0e-4, 800.0, 800.0),
                 PILoop("h2", "qb", 4.0e-3, 100.0, 100.0)),
}


def _initial_inputs(values: Any, problem: ControlProblem) -> dict[str, float]:
    """Check the ``initial_inputs`` option: plant input name → finite number."""
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise CosimError(f"controller 'pi': initial_inputs must map inputs to numbers, "
                         f"got {values!r}")
    out = {}
    for name, value in values.items():
        if name not in problem.inputs:
            raise CosimError(f"controller 'pi': initial_inputs: unknown input {name!r} "
                             f"(inputs: {', '.join(problem.inputs)})")
        if (isinstance(value, bool) or not isinstance(value, int | float)
                or not math.isfinite(value)):
            raise CosimError(f"controller 'pi': initial_inputs: {name} must be a finite "
                             f"number, got {value!r}")
        out[name] = float(value)
    return out


class PIController(Component):
    """Decentralised PI with anti-windup and input saturation (see the module docstring).

    Parameters
    ----------
    problem : ControlProblem
        Signals, bounds and sample time (default :data:`controllers.problem.FOURTANK`).
    pairing : {"cross", "diagonal"} or tuple of PILoop
        Which input controls which output, with the loop tunings.
    initial_inputs : dict, optional
        Inputs at the first step (integrator initial values); default mid-range.
    """

    direct_feedthrough = True

    def __init__(self, problem: ControlProblem = FOURTANK,
                 pairing: str | tuple[PILoop, ...] = "cross",
                 initial_inputs: Mapping[str, float] | None = None) -> None:
        self.name = "pi"
        self.problem = problem
        if isinstance(pairing, str):
            if pairing not in PAIRINGS:
                raise CosimError(f"controller 'pi': unknown pairing {pairing!r} (known: "
                                 f"{', '.join(PAIRINGS)})")
            self.loops = PAIRINGS[pairing]
        elif isinstance(pairing, tuple | list) and all(isinstance(p, PILoop) for p in pairing):
            self.loops = tuple(pairing)
        else:
            raise CosimError(f"controller 'pi': pairing must be one of {', '.join(PAIRINGS)}, "
                             f"got {pairing!r}")
        self.sample_time = problem.Ts
        self.bounds = problem.bounds()
        self.inputs = tuple(Signal(y, unit) for y, unit in
                            zip(problem.outputs, problem.output_units, strict=True)) + tuple(
            Signal(f"ref.{y}", unit) for y, unit in
            zip(problem.outputs, problem.output_units, strict=True))
        self.outputs = tuple(Signal(u, unit) for u, unit in
                             zip(problem.inputs, problem.input_units, strict=True))
        self.initial_inputs = _initial_inputs(initial_inputs, problem)
        self._values: dict[str, float] = {}
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        """Reset integrators to the initial inputs."""
        self._I = {}
        for loop in self.loops:
            lo, hi = self.bounds[loop.u]
            self._I[loop.u] = self.initial_inputs.get(loop.u, 0.5 * (lo + hi))
        self._u = dict(self._I)
        self._sat_steps = dict.fromkeys(self._u, 0)
        self._steps = 0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Measured outputs and set-points (``ref.<y>``)."""
        self._values.update(values)

    def step(self, t: float, dt: float) -> None:
        """One PI update per loop; ``dt`` is the sample interval."""
        vals = self._values
        for loop in self.loops:
            e = vals[f"ref.{loop.y}"] - vals[loop.y]
            v = self._I[loop.u] + loop.K * e
            lo, hi = self.bounds[loop.u]
            u = hi if v > hi else lo if v < lo else v
            if u != v:
                self._sat_steps[loop.u] += 1
            self._I[loop.u] += loop.K * dt / loop.Ti * e + dt / loop.Tt * (u - v)
            self._u[loop.u] = u
        self._steps += 1

    def get_outputs(self) -> dict[str, float]:
        """Inputs to apply [m3/s]."""
        return dict(self._u)

    def diagnostics(self) -> dict[str, float]:
        """Integrator states ``int_<u>`` [input units]."""
        return {f"int_{u}": i for u, i in self._I.items()}

    def summary(self) -> dict:
        """Loop pairing and how often each input saturated."""
        return {"pairing": {lp.y: lp.u for lp in self.loops}, "steps": self._steps,
                "saturated_steps": dict(self._sat_steps)}
