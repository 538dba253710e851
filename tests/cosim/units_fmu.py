"""A small plant FMU that declares units, for the problem binding's tests
(:mod:`cosim.core.binding`).

``Reactor.fmu`` (pythonfmu, FMI 2.0 Co-Simulation) is a CSTR-like stirred tank with its
variables in the units a third party might choose: feed flow ``F_in`` [m3/s], coolant
temperature ``Tc`` [degC], concentration ``CA`` [mol/m3], temperature ``T`` [degC]:

    dCA/dt = F/V (CAf − CA) − k0 CA,      dT/dt = F/V (Tf − T) + UA (Tc − T)

(V = 0.01 m3, CAf = 1000 mol/m3, Tf = 20 degC, UA = 5e-3 1/s, tunable k0 = 1e-3 1/s; explicit
Euler in substeps of 0.5 s). Echo outputs return what the FMU received (``F_echo`` [m3/s],
``Tc_echo`` [degC], ``k_echo`` [1/s]), so that a test sees the converted values on the FMU's
side. For the error cases it also has ``level`` [m] (an output of another dimension),
``mode`` (an Integer output), ``V`` (a fixed parameter) and ``UA`` (a tunable one).

pythonfmu writes no units; :meth:`Reactor.to_xml` adds them and their ``UnitDefinitions``
(``Lpm`` [m3/s × 1/60000] is a unit only the FMU defines: pint does not know it).

:data:`PROBLEM` is the control problem in other units (L/min, K, mol/L, K), with the FMU's
own name of the feed flow (``variable = "F_in"``) and PI loops; :data:`SCENARIO` a set-point
sequence for it.
"""

from __future__ import annotations

from pathlib import Path

SOURCE = '''
from xml.etree.ElementTree import SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real

#: name -> (exponents, factor, offset): value_SI = factor * value + offset
UNITS = {
    "m3/s": ({"m": 3, "s": -1}, 1.0, 0.0),
    "Lpm": ({"m": 3, "s": -1}, 1.0 / 60000.0, 0.0),
    "degC": ({"K": 1}, 1.0, 273.15),
    "K": ({"K": 1}, 1.0, 0.0),
    "mol/m3": ({"mol": 1, "m": -3}, 1.0, 0.0),
    "m": ({"m": 1}, 1.0, 0.0),
    "1/s": ({"s": -1}, 1.0, 0.0),
}
VARIABLE_UNITS = {"F_in": "m3/s", "F_echo": "m3/s", "Tc": "degC", "Tc_echo": "degC",
                  "CA": "mol/m3", "T": "degC", "level": "m", "k0": "1/s", "k_echo": "1/s",
                  "UA": "1/s"}


class Reactor(Fmi2Slave):
    author = "tests"
    description = "CSTR-like tank with units (m3/s, degC, mol/m3)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.F_in, self.Tc = 1.0 / 60000.0, 25.0
        self.k0, self.UA, self.V = 1e-3, 5e-3, 0.01
        q = self.F_in / self.V
        self.CA = 1000.0 * q / (q + self.k0)
        self.T = (q * 20.0 + self.UA * self.Tc) / (q + self.UA)
        self.F_echo, self.Tc_echo, self.k_echo = self.F_in, self.Tc, self.k0
        self.level, self.mode = 1.0, 1
        for name in ("F_in", "Tc"):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous))
        for name in ("CA", "T", "F_echo", "Tc_echo", "k_echo", "level"):
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous))
        self.register_variable(Integer("mode", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete))
        for name in ("k0", "UA"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))
        self.register_variable(Real("V", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed))

    def to_xml(self, model_options=None):
        root = super().to_xml(model_options or {})
        units = SubElement(root, "UnitDefinitions")
        for name, (exps, factor, offset) in UNITS.items():
            unit = SubElement(units, "Unit", {"name": name})
            attrs = {k: str(v) for k, v in exps.items()}
            if factor != 1.0:
                attrs["factor"] = repr(factor)
            if offset != 0.0:
                attrs["offset"] = repr(offset)
            SubElement(unit, "BaseUnit", attrs)
        root.remove(units)
        root.insert(list(root).index(root.find("CoSimulation")) + 1, units)
        for var in root.find("ModelVariables"):
            unit = VARIABLE_UNITS.get(var.get("name"))
            if unit:
                var.find("Real").set("unit", unit)
        structure = root.find("ModelStructure")
        if structure.find("InitialUnknowns") is None:
            initial = SubElement(structure, "InitialUnknowns")
            for unknown in structure.find("Outputs"):
                SubElement(initial, "Unknown", {"index": unknown.get("index")})
        return root

    def do_step(self, current_time, step_size):
        n = max(1, int(round(step_size / 0.5)))
        dt = step_size / n
        q = self.F_in / self.V
        for _ in range(n):
            dca = q * (1000.0 - self.CA) - self.k0 * self.CA
            dT = q * (20.0 - self.T) + self.UA * (self.Tc - self.T)
            self.CA += dt * dca
            self.T += dt * dT
        self.F_echo, self.Tc_echo, self.k_echo = self.F_in, self.Tc, self.k0
        return True
'''

#: The reactor's control problem, in other units than the FMU's.
PROBLEM = '''\
[problem]
name = "reactor"
Ts = 10.0
description = "CSTR-like tank: F, Tc -> CA, T"

[inputs.F]
unit = "L/min"
variable = "F_in"
min = 0.5
max = 2.0
hold = [2, 20]

[inputs.Tc]
unit = "K"
min = 283.15
max = 343.15
hold = [2, 20]

[outputs.CA]
unit = "mol/L"
min = 0.3
max = 0.9

[outputs.T]
unit = "K"
min = 283.15
max = 343.15

[pi]
pairing = "main"

[pi.pairings]
main = [
    { output = "CA", input = "F", K = 2.0, Ti = 300.0 },
    { output = "T", input = "Tc", K = 1.0, Ti = 150.0 },
]
'''

#: Set-points for :data:`PROBLEM` (the run starts at rest: CA 0.625 mol/L, T 296.9 K).
SCENARIO = '''\
time,ref.CA,ref.T
0,0.625,296.9
1000,0.7,
2000,,305.0
3000,,
'''


def build(dest: Path) -> Path:
    """Build ``Reactor.fmu`` into ``dest`` and return its path."""
    from pythonfmu.builder import FmuBuilder

    dest.mkdir(parents=True, exist_ok=True)
    script = dest / "reactor.py"
    script.write_text(SOURCE)
    return Path(FmuBuilder.build_FMU(script, dest=dest))
