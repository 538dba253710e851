"""A third-party quadruple-tank plant, exported by pythonfmu (FMI 2.0 Co-Simulation).

This is the worked example of "Use your own plant FMU": a four-tank process as another team
would ship it. It differs from the project's C plant (``fmus/fourtank``) in

* parameters: tank area 0.062 m² (+3 %), outlet areas a few % off, valve splits
  ``split_a = 0.35``, ``split_b = 0.45`` (the paper's plant: 0.3, 0.4);
* names and units: pump flows ``Fa``, ``Fb`` and extra inflows ``Fin1``..``Fin4`` in l/min,
  levels ``L1``..``L4`` in cm, outlet areas ``outlet1``..``outlet4`` in cm², start levels
  ``L1_0``..``L4_0`` in cm.

Equations (the paper's section V, ``sec:numerical-example``, with extra inflows)::

    dh1/dt = (-a1 sqrt(2 g h1) + a3 sqrt(2 g h3) + split_a qa       + qd1) / A
    dh2/dt = (-a2 sqrt(2 g h2) + a4 sqrt(2 g h4) + split_b qb       + qd2) / A
    dh3/dt = (-a3 sqrt(2 g h3)                   + (1 - split_b) qb + qd3) / A
    dh4/dt = (-a4 sqrt(2 g h4)                   + (1 - split_a) qa + qd4) / A

integrated in SI units by classical RK4 with fixed substeps of at most 0.25 s (levels clamped
at 0 after each substep), so a run is deterministic. The default start levels are the
steady state with ``L1 = L2 = 65 cm``.

pythonfmu writes no units into modelDescription.xml; :meth:`QuadrupleTank.to_xml` adds them
(and their ``UnitDefinitions``) so that a variable map's units can be checked.

Build with ``python fmus/thirdparty/build.py --out DIR``. The FMU runs in a Python host that
has pythonfmu installed (the project's venv).
"""

from __future__ import annotations

import math
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

G = 9.81
#: Unit name -> (SI base-unit exponents, factor to SI).
UNITS = {
    "l/min": ({"m": 3, "s": -1}, 1.0 / 60000.0),
    "cm": ({"m": 1}, 0.01),
    "cm2": ({"m": 2}, 1e-4),
    "m2": ({"m": 2}, 1.0),
}
#: Units written into modelDescription.xml, by variable name.
VARIABLE_UNITS = {"Fa": "l/min", "Fb": "l/min", **{f"Fin{i}": "l/min" for i in range(1, 5)},
                  **{f"L{i}": "cm" for i in range(1, 5)},
                  **{f"L{i}_0": "cm" for i in range(1, 5)},
                  **{f"outlet{i}": "cm2" for i in range(1, 5)}, "area": "m2"}
#: Maximum integration substep [s].
MAX_SUBSTEP = 0.25


def steady_state(h1: float, h2: float, a: list[float], ga: float, gb: float) -> list[float]:
    """Levels [m] of the steady state with bottom levels ``h1``, ``h2`` (no extra inflow)."""
    o1, o2 = a[0] * math.sqrt(2 * G * h1), a[1] * math.sqrt(2 * G * h2)
    # o1 = ga qa + (1 - gb) qb, o2 = (1 - ga) qa + gb qb
    det = ga * gb - (1 - ga) * (1 - gb)
    qa = (gb * o1 - (1 - gb) * o2) / det
    qb = (ga * o2 - (1 - ga) * o1) / det
    h3 = ((1 - gb) * qb / a[2]) ** 2 / (2 * G)
    h4 = ((1 - ga) * qa / a[3]) ** 2 / (2 * G)
    return [h1, h2, h3, h4]


class QuadrupleTank(Fmi2Slave):
    """Quadruple-tank process: l/min in, cm out (see the module docstring)."""

    author = "ACME Process Models (example third party)"
    description = "Quadruple-tank process, l/min pumps, cm levels (pythonfmu)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.area = 0.062                       # m2
        self.outlet1, self.outlet2 = 1.35, 1.47  # cm2
        self.outlet3, self.outlet4 = 0.90, 0.91  # cm2
        self.split_a, self.split_b = 0.35, 0.45
        self.Fa = self.Fb = 0.0                  # l/min
        self.Fin1 = self.Fin2 = self.Fin3 = self.Fin4 = 0.0
        start = steady_state(0.65, 0.65, self._outlets_m2(), self.split_a, self.split_b)
        self.L1_0, self.L2_0, self.L3_0, self.L4_0 = (100.0 * h for h in start)
        self._h = list(start)
        self.L1, self.L2, self.L3, self.L4 = (100.0 * h for h in start)

        for name, what in (("Fa", "pump A (split_a to tank 1)"),
                           ("Fb", "pump B (split_b to tank 2)")):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous,
                                        description=f"Flow of {what}"))
        for i in range(1, 5):
            self.register_variable(Real(f"Fin{i}", causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous,
                                        description=f"Extra inflow into tank {i} (<0: leak)"))
        for i in range(1, 5):
            self.register_variable(Real(f"L{i}", causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        description=f"Level of tank {i}"))
        self.register_variable(Real("area", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable,
                                    description="Cross-section of each tank"))
        for i in range(1, 5):
            self.register_variable(Real(f"outlet{i}", causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable,
                                        description=f"Outlet area of tank {i}"))
        for name, i in (("split_a", 1), ("split_b", 2)):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable,
                                        description=f"Fraction of pump flow to tank {i}"))
        for i in range(1, 5):
            self.register_variable(Real(f"L{i}_0", causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed,
                                        description=f"Initial level of tank {i}"))

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus units (``UnitDefinitions``) and initial unknowns."""
        root = super().to_xml(model_options or {})
        units = SubElement(root, "UnitDefinitions")
        for name, (exps, factor) in UNITS.items():
            unit = SubElement(units, "Unit", {"name": name})
            attrs = {k: str(v) for k, v in exps.items()}
            if factor != 1.0:
                attrs["factor"] = repr(factor)
            SubElement(unit, "BaseUnit", attrs)
        # FMI 2.0 schema order: CoSimulation, UnitDefinitions, ..., ModelVariables.
        root.remove(units)
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, units)
        for var in root.find("ModelVariables"):
            unit = VARIABLE_UNITS.get(var.get("name"))
            if unit:
                var.find("Real").set("unit", unit)
        # Outputs are "calculated" during initialisation: list them as initial unknowns
        # (pythonfmu leaves this out; fmpy validate asks for it).
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None and structure.find("InitialUnknowns") is None:
            initial = SubElement(structure, "InitialUnknowns")
            for unknown in outputs:
                SubElement(initial, "Unknown", {"index": unknown.get("index")})
        return root

    def _outlets_m2(self) -> list[float]:
        return [1e-4 * x for x in (self.outlet1, self.outlet2, self.outlet3, self.outlet4)]

    def exit_initialization_mode(self):
        self._h = [max(0.0, 0.01 * x) for x in (self.L1_0, self.L2_0, self.L3_0, self.L4_0)]
        self._publish()

    def _publish(self) -> None:
        self.L1, self.L2, self.L3, self.L4 = (100.0 * h for h in self._h)

    def _rhs(self, h: list[float], q: tuple[float, ...]) -> list[float]:
        qa, qb, qd1, qd2, qd3, qd4 = q
        a = self._outlets_m2()
        out = [ai * math.sqrt(2.0 * G * max(hi, 0.0)) for ai, hi in zip(a, h, strict=True)]
        ga, gb, s = self.split_a, self.split_b, self.area
        return [(-out[0] + out[2] + ga * qa + qd1) / s,
                (-out[1] + out[3] + gb * qb + qd2) / s,
                (-out[2] + (1.0 - gb) * qb + qd3) / s,
                (-out[3] + (1.0 - ga) * qa + qd4) / s]

    def do_step(self, current_time: float, step_size: float) -> bool:
        q = tuple(x / 60000.0 for x in (self.Fa, self.Fb, self.Fin1, self.Fin2, self.Fin3,
                                         self.Fin4))
        n = max(1, math.ceil(step_size / MAX_SUBSTEP - 1e-9))
        dt = step_size / n
        h = self._h
        for _ in range(n):
            k1 = self._rhs(h, q)
            k2 = self._rhs([x + 0.5 * dt * k for x, k in zip(h, k1, strict=True)], q)
            k3 = self._rhs([x + 0.5 * dt * k for x, k in zip(h, k2, strict=True)], q)
            k4 = self._rhs([x + dt * k for x, k in zip(h, k3, strict=True)], q)
            h = [max(0.0, x + dt / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4))
                 for x, p1, p2, p3, p4 in zip(h, k1, k2, k3, k4, strict=True)]
        if not all(math.isfinite(x) for x in h):
            return False
        self._h = h
        self._publish()
        return True
