"""The shared machinery of the example plants (pythonfmu, FMI 2.0 Co-Simulation).

Each example plant (``cstr/cstr.py``, ``heater/heater.py``, ``mixing_tank/mixing_tank.py``)
is an ordinary differential equation ``dx/dt = rhs(x, u, p)`` with outputs ``y = out(x, u, p)``,
declared as class attributes (inputs, outputs and tunable parameters with their units and
start values). This base registers the FMU variables, integrates with classical RK4 in fixed
substeps (deterministic: the same inputs give the same outputs on every machine), starts the
state at rest for the start inputs (the steady state, found by integrating), and writes the
units into modelDescription.xml (``UnitDefinitions`` with SI base-unit exponents and factors),
which pythonfmu leaves out.

The file is bundled into each FMU (``build.py`` passes it as a project file).
"""

from __future__ import annotations

import math
from typing import ClassVar
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

#: Unit name -> (SI base-unit exponents, factor, offset): value_SI = factor * value + offset.
UNITS: dict[str, tuple[dict[str, int], float, float]] = {
    "L/min": ({"m": 3, "s": -1}, 1.0 / 60000.0, 0.0),
    "L/s": ({"m": 3, "s": -1}, 1e-3, 0.0),
    "K": ({"K": 1}, 1.0, 0.0),
    "degC": ({"K": 1}, 1.0, 273.15),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0, 0.0),
    "mol/L": ({"mol": 1, "m": -3}, 1000.0, 0.0),
    "kg/h": ({"kg": 1, "s": -1}, 1.0 / 3600.0, 0.0),
    "m": ({"m": 1}, 1.0, 0.0),
    "1": ({}, 1.0, 0.0),
}


class ExamplePlant(Fmi2Slave):
    """An ODE plant: subclasses declare the signals and implement :meth:`rhs` and
    :meth:`out` (see the module docstring).

    Class attributes
    ----------------
    INPUTS, OUTPUTS, PARAMETERS : tuple of (name, unit, start, description)
    DEAD_TIME : dict of str to float
        Transport delay of an input [s]: the ODE sees the value applied that long ago (the
        start value before). Default: none.
    STATES : int
        Number of states.
    MAX_SUBSTEP : float
        Longest RK4 substep [s].
    SETTLE : float
        How long the start inputs are integrated to find the state at rest [s].
    """

    INPUTS: tuple[tuple[str, str, float, str], ...] = ()
    OUTPUTS: tuple[tuple[str, str, float, str], ...] = ()
    PARAMETERS: tuple[tuple[str, str, float, str], ...] = ()
    DEAD_TIME: ClassVar[dict[str, float]] = {}
    STATES = 1
    MAX_SUBSTEP = 1.0
    SETTLE = 5000.0

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for table, causality, variability in (
                (self.INPUTS, Fmi2Causality.input, Fmi2Variability.continuous),
                (self.OUTPUTS, Fmi2Causality.output, Fmi2Variability.continuous),
                (self.PARAMETERS, Fmi2Causality.parameter, Fmi2Variability.tunable)):
            for name, _unit, start, description in table:
                setattr(self, name, float(start))
                self.register_variable(Real(name, causality=causality,
                                            variability=variability, description=description))
        self._x = [0.0] * self.STATES
        #: per delayed input: (time applied, value), oldest first
        self._applied: dict[str, list[tuple[float, float]]] = {n: [] for n in self.DEAD_TIME}
        self._now: dict[str, float] = {}

    # -- the model (subclasses) -----------------------------------------------------------
    def rhs(self, x: list[float]) -> list[float]:
        """``dx/dt`` at state ``x`` with the current inputs and parameters."""
        raise NotImplementedError

    def out(self, x: list[float]) -> dict[str, float]:
        """The outputs at state ``x``."""
        raise NotImplementedError

    def x_guess(self) -> list[float]:
        """Where the settling integration starts."""
        return [1.0] * self.STATES

    # -- FMI --------------------------------------------------------------------------------
    def exit_initialization_mode(self):
        # a delayed input has held its start value since always (the plant at rest)
        self._applied = {n: [(-math.inf, float(getattr(self, n)))] for n in self.DEAD_TIME}
        x = self.x_guess()
        self._x = self._integrate(x, self.SETTLE)
        self._publish()

    def do_step(self, current_time: float, step_size: float) -> bool:
        x = self._integrate(self._x, step_size, current_time)
        if not all(math.isfinite(v) for v in x):
            return False
        self._x = x
        self._publish()
        return True

    def _publish(self) -> None:
        for name, value in self.out(self._x).items():
            setattr(self, name, float(value))

    def _integrate(self, x: list[float], span: float, t0: float | None = None) -> list[float]:
        n = max(1, math.ceil(span / self.MAX_SUBSTEP - 1e-9))
        dt = span / n
        held = self._delayed_inputs(t0) if t0 is not None else {}
        for k in range(n):
            for name, history in held.items():   # the value applied DEAD_TIME ago
                setattr(self, name, _at(history, t0 + k * dt - self.DEAD_TIME[name]))
            k1 = self.rhs(x)
            k2 = self.rhs([a + 0.5 * dt * k for a, k in zip(x, k1, strict=True)])
            k3 = self.rhs([a + 0.5 * dt * k for a, k in zip(x, k2, strict=True)])
            k4 = self.rhs([a + dt * k for a, k in zip(x, k3, strict=True)])
            x = [a + dt / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
                 for a, p1, p2, p3, p4 in zip(x, k1, k2, k3, k4, strict=True)]
            x = self.clamp(x)
        for name, value in self._now.items():   # the inputs as set, for the next step
            setattr(self, name, value)
        return x

    def _delayed_inputs(self, t0: float) -> dict[str, list[tuple[float, float]]]:
        """Record the delayed inputs' values set for the step from ``t0``; their histories."""
        for name, history in self._applied.items():
            value = float(getattr(self, name))
            self._now[name] = value
            history.append((t0, value))
            horizon = t0 - self.DEAD_TIME[name] - 1e-9
            while len(history) > 2 and history[1][0] <= horizon:
                history.pop(0)
        return self._applied

    def clamp(self, x: list[float]) -> list[float]:
        """Keep a state physical after each substep (default: unchanged)."""
        return x

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus ``UnitDefinitions``, each variable's unit, and the
        outputs as initial unknowns (fmpy validate asks for them)."""
        root = super().to_xml(model_options or {})
        declared = {name: unit for table in (self.INPUTS, self.OUTPUTS, self.PARAMETERS)
                    for name, unit, _s, _d in table}
        used = sorted(set(declared.values()))
        units = Element("UnitDefinitions")
        for name in used:
            exps, factor, offset = UNITS[name]
            attrs = {k: str(v) for k, v in exps.items()}
            if factor != 1.0:
                attrs["factor"] = repr(factor)
            if offset != 0.0:
                attrs["offset"] = repr(offset)
            SubElement(SubElement(units, "Unit", {"name": name}), "BaseUnit", attrs)
        # FMI 2.0 schema order: CoSimulation, UnitDefinitions, ..., ModelVariables
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, units)
        for var in root.find("ModelVariables"):
            unit = declared.get(var.get("name"))
            if unit:
                var.find("Real").set("unit", unit)
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None and structure.find("InitialUnknowns") is None:
            initial = SubElement(structure, "InitialUnknowns")
            for unknown in outputs:
                SubElement(initial, "Unknown", {"index": unknown.get("index")})
        return root


def _at(history: list[tuple[float, float]], t: float) -> float:
    """The value applied last at or before ``t`` (a zero-order hold)."""
    value = history[0][1]
    for when, v in history:
        if when <= t + 1e-9:
            value = v
        else:
            break
    return value
