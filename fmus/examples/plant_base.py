"""The shared machinery of the example plants (pythonfmu, FMI 2.0 Co-Simulation).

A plant is its tables and its equations. Each example plant (``cstr/cstr.py``,
``heater/heater.py``, ...) is an ordinary differential equation ``dx/dt = rhs(x)`` over its
current inputs and parameters (attributes of the plant). Its signals are one table,
``SIGNALS``, a line each: the kind (``input``, ``output``, ``parameter`` (tunable), ``state``),
the name, the unit, the start value and the description (the rest of the line)::

    SIGNALS = '''
        input      P         W     1000.0  heater power
        output     T         degC  45.0    vessel temperature
        parameter  C_factor  1     1.0     multiplies the heat capacity
    '''

Without ``state`` lines the states are the outputs, in their order: the settling starts from
the outputs' start values and the outputs are the states. With them the settling starts from
the states' start values and an output named as a state is that state; a plant whose outputs
are other functions of its states gives :meth:`ExamplePlant.out`. A plant made of
first-order-plus-dead-time channels, as the field's identified benchmarks are published
(``G_ij(s) = K_ij exp(-theta_ij s) / (tau_ij s + 1)``), is its signals and three matrices:
:class:`TransferFunctionPlant`.

This base registers the FMU variables, integrates with classical RK4 in fixed substeps
(deterministic: the same inputs give the same outputs on every machine), delays inputs (an
input's own dead time, ``DEAD_TIME``, or any past value the equations ask for with
:meth:`ExamplePlant.applied`: a dead time per channel), starts the state at rest for the
start inputs (the steady state, found by integrating), and writes the units into
modelDescription.xml (``UnitDefinitions`` with SI base-unit exponents and factors), which
pythonfmu leaves out.

The file is bundled into each FMU (``build.py`` passes it as a project file).
"""

from __future__ import annotations

import math
import sys
from typing import Any, ClassVar
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

#: Unit name -> (SI base-unit exponents, factor, offset): value_SI = factor * value + offset.
UNITS: dict[str, tuple[dict[str, int], float, float]] = {
    "L/min": ({"m": 3, "s": -1}, 1.0 / 60000.0, 0.0),
    "L/s": ({"m": 3, "s": -1}, 1e-3, 0.0),
    "mL/s": ({"m": 3, "s": -1}, 1e-6, 0.0),
    "lb/min": ({"kg": 1, "s": -1}, 0.45359237 / 60.0, 0.0),
    "K": ({"K": 1}, 1.0, 0.0),
    "degC": ({"K": 1}, 1.0, 273.15),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0, 0.0),
    "kW": ({"kg": 1, "m": 2, "s": -3}, 1000.0, 0.0),
    "mol/L": ({"mol": 1, "m": -3}, 1000.0, 0.0),
    "mol%": ({}, 0.01, 0.0),
    "kg/h": ({"kg": 1, "s": -1}, 1.0 / 3600.0, 0.0),
    "1/h": ({"s": -1}, 1.0 / 3600.0, 0.0),
    "m": ({"m": 1}, 1.0, 0.0),
    "cm": ({"m": 1}, 0.01, 0.0),
    "pH": ({}, 1.0, 0.0),
    "1": ({}, 1.0, 0.0),
}

#: A signal of a plant: (name, unit, start value, description).
Signal = tuple[str, str, float, str]
#: The kinds of line of ``SIGNALS`` and the table each fills.
KINDS = {"input": "INPUTS", "output": "OUTPUTS", "parameter": "PARAMETERS", "state": "STATE"}
#: The plant scripts' namespaces, once per class made (see ExamplePlant.__init_subclass__).
_HELD: list[dict[str, Any]] = []


class ExamplePlant(Fmi2Slave):
    """An ODE plant: subclasses declare the signals and implement :meth:`rhs` (see the
    module docstring).

    Class attributes
    ----------------
    SIGNALS : str
        The signals' table (see the module docstring): it fills ``INPUTS``, ``OUTPUTS``,
        ``PARAMETERS`` and ``STATE``, tuples of (name, unit, start, description) in its order.
    DEAD_TIME : dict of str to float
        Transport delay of an input [s]: the equations see the value applied that long ago
        (the start value before). Default: none.
    STATES : int
        Number of states: the ``state`` lines, else the outputs.
    MAX_SUBSTEP : float
        Longest RK4 substep [s].
    SETTLE : float or None
        How long the start inputs are integrated to find the state at rest [s]; ``None``
        (the default): until it rests (no state moves by more than 1e-13 of itself over 100
        substeps, at most a million substeps).
    """

    author = "gru-mpc-cosim examples"
    SIGNALS = ""
    INPUTS: tuple[Signal, ...] = ()
    OUTPUTS: tuple[Signal, ...] = ()
    PARAMETERS: tuple[Signal, ...] = ()
    STATE: tuple[Signal, ...] = ()
    DEAD_TIME: ClassVar[dict[str, float]] = {}
    STATES = 0
    MAX_SUBSTEP = 1.0
    SETTLE: float | None = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        # pythonfmu 0.7 runs the plant script again at each instantiation (its findClass, to
        # find the class) and then gives up a reference to the script's namespace that it never
        # held (a Py_DECREF of PyModule_GetDict's borrowed dict): hold one each time the class
        # is made, or a script's namespace is freed under its FMU (measured: a table-only
        # plant, whose functions hold no reference to it, crashed at its second instance)
        module = sys.modules.get(cls.__module__)
        if module is not None:
            _HELD.append(vars(module))
        if "description" not in cls.__dict__ and cls.__doc__:
            cls.description = cls.__doc__.strip().splitlines()[0]   # pythonfmu's description
        if "SIGNALS" in cls.__dict__:
            for attr, table in signal_tables(cls.SIGNALS, cls.__name__).items():
                setattr(cls, attr, table)
            cls.STATES = len(cls.STATE) or len(cls.OUTPUTS)

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
        #: per input with a history: (time applied, value), oldest first
        self._applied: dict[str, list[tuple[float, float]]] = {n: [] for n in self.lookback()}
        self._now: dict[str, float] = {}
        #: start of the substep being integrated [s] (None while settling)
        self._t: float | None = None

    # -- the model (subclasses) -----------------------------------------------------------
    def rhs(self, x: list[float]) -> list[float]:
        """``dx/dt`` at state ``x`` with the current inputs and parameters."""
        raise NotImplementedError

    def out(self, x: list[float]) -> dict[str, float]:
        """The outputs at state ``x`` (default: the states of the outputs' names; without
        ``state`` lines the states, in the outputs' order)."""
        if not self.STATE:
            return {name: v for (name, _u, _s, _d), v in zip(self.OUTPUTS, x, strict=True)}
        index = {name: i for i, (name, _u, _s, _d) in enumerate(self.STATE)}
        return {name: x[index[name]] for name, _u, _s, _d in self.OUTPUTS}

    def x_guess(self) -> list[float]:
        """Where the settling integration starts (default: the states' start values; without
        ``state`` lines the outputs')."""
        return [start for _n, _u, start, _d in self.STATE or self.OUTPUTS]

    def clamp(self, x: list[float]) -> list[float]:
        """Keep a state physical after each substep (default: unchanged)."""
        return x

    def lookback(self) -> dict[str, float]:
        """How far back [s] the equations read each input that has a history (default: the
        inputs' ``DEAD_TIME``; a plant reading :meth:`applied` adds its own)."""
        return dict(self.DEAD_TIME)

    def applied(self, name: str, delay: float) -> float:
        """The value of input ``name`` applied ``delay`` seconds before the substep being
        integrated (its value now while settling); ``delay`` at most its :meth:`lookback`."""
        if self._t is None:
            return float(getattr(self, name))
        return _at(self._applied[name], self._t - delay)

    # -- FMI --------------------------------------------------------------------------------
    def exit_initialization_mode(self):
        # a delayed input has held its start value since always (the plant at rest)
        self._applied = {n: [(-math.inf, float(getattr(self, n)))] for n in self.lookback()}
        self._x = self._settle(self.x_guess())
        self._publish()

    def do_step(self, current_time: float, step_size: float) -> bool:
        x = self._integrate(self._x, step_size, current_time)
        if not all(math.isfinite(v) for v in x):
            return False
        self._x = x
        self._publish()
        return True

    def _settle(self, x: list[float]) -> list[float]:
        """The state at rest for the inputs now, integrated from ``x`` (``SETTLE``)."""
        if self.SETTLE is not None:
            return self._integrate(x, self.SETTLE)
        for _ in range(10_000):
            y = self._integrate(x, 100 * self.MAX_SUBSTEP)
            if all(abs(a - b) <= 1e-13 * (1.0 + abs(b)) for a, b in zip(x, y, strict=True)):
                return y
            x = y
        return x

    def _publish(self) -> None:
        for name, value in self.out(self._x).items():
            setattr(self, name, float(value))

    def _integrate(self, x: list[float], span: float, t0: float | None = None) -> list[float]:
        n = max(1, math.ceil(span / self.MAX_SUBSTEP - 1e-9))
        dt = span / n
        held = self._delayed_inputs(t0) if t0 is not None else {}
        for k in range(n):
            self._t = None if t0 is None else t0 + k * dt
            for name, delay in self.DEAD_TIME.items():   # the value applied DEAD_TIME ago
                if name in held:
                    setattr(self, name, _at(held[name], t0 + k * dt - delay))
            k1 = self.rhs(x)
            k2 = self.rhs([a + 0.5 * dt * k for a, k in zip(x, k1, strict=True)])
            k3 = self.rhs([a + 0.5 * dt * k for a, k in zip(x, k2, strict=True)])
            k4 = self.rhs([a + dt * k for a, k in zip(x, k3, strict=True)])
            x = [a + dt / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
                 for a, p1, p2, p3, p4 in zip(x, k1, k2, k3, k4, strict=True)]
            x = self.clamp(x)
        self._t = None
        for name, value in self._now.items():   # the inputs as set, for the next step
            setattr(self, name, value)
        return x

    def _delayed_inputs(self, t0: float) -> dict[str, list[tuple[float, float]]]:
        """Record the values set for the step from ``t0`` of the inputs with a history; their
        histories (kept as far back as :meth:`lookback` reads)."""
        span = self.lookback()
        for name, history in self._applied.items():
            value = float(getattr(self, name))
            self._now[name] = value
            history.append((t0, value))
            horizon = t0 - span[name] - 1e-9
            while len(history) > 2 and history[1][0] <= horizon:
                history.pop(0)
        return self._applied

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


class FurnacePlant(ExamplePlant):
    """Heated zones of one electric furnace (the furnace, furnace_load and furnace3 examples):
    their constants (heat capacity ``C`` [J/K], losses to the room ``UA`` [W/K], exchange
    between neighbouring zones ``K`` [W/K], radiation ``E`` [W/K^4]), their tunable room
    temperature and factors (:data:`PARAMETERS`, appended to each plant's own signals) and
    their integration settings; each plant writes its zones' equations."""

    C, UA, K, E = 1.0e4, 5.0, 12.0, 1.2e-8
    #: the furnaces' tunable parameters (``T_amb`` described by :data:`AMBIENT`)
    PARAMETERS = """
        parameter  K_factor  1     1.0     multiplies the heat exchange between the zones
        parameter  C_factor  1     1.0     multiplies the zones' heat capacity
    """
    AMBIENT = "        parameter  T_amb     degC  20.0    room temperature"
    MAX_SUBSTEP = 2.0
    SETTLE = 20000.0


class TransferFunctionPlant(ExamplePlant):
    """A plant of first-order-plus-dead-time channels around an operating point::

        y_i(t) = y0_i + sum_j x_ij(t),
        tau_ij dx_ij/dt = K_ij (u_j(t - theta_ij) - u0_j) - x_ij      (K_ij != 0)

    ``u`` are all the plant's inputs (manipulated and measured disturbances alike, in the
    order of the ``input`` lines of ``SIGNALS``), ``u0`` and ``y0`` the start values of the
    inputs and outputs (the published operating point: the model is in deviation variables
    around it). Each
    channel has its own dead time, read from its input's history (:meth:`applied`); the
    integration is exact where every dead time is a whole number of substeps.

    Class attributes
    ----------------
    GAIN, TAU, DEAD : tuple of rows (one per output) of one number per input
        ``K_ij`` [output unit per input unit], ``tau_ij`` and ``theta_ij`` [``TIME_UNIT``];
        a zero gain: no channel.
    TIME_UNIT : float
        Seconds per unit of ``TAU`` and ``DEAD`` (60: the published minutes).

    Tunable parameters: ``gain_factor`` and ``tau_factor`` (``parameter`` lines of
    ``SIGNALS``) multiply every gain and time constant; a plant with its own uncertainty
    structure overrides :meth:`gain` and :meth:`tau` instead.
    """

    GAIN: tuple[tuple[float, ...], ...] = ()
    TAU: tuple[tuple[float, ...], ...] = ()
    DEAD: tuple[tuple[float, ...], ...] = ()
    TIME_UNIT = 60.0
    #: (output row, input column) of each channel: the states, in order
    CHANNELS: ClassVar[tuple[tuple[int, int], ...]] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        shape = (len(cls.OUTPUTS), len(cls.INPUTS))
        for table in (cls.GAIN, cls.TAU, cls.DEAD):
            if (len(table), len({len(row) for row in table} | {shape[1]})) != (shape[0], 1):
                raise TypeError(f"{cls.__name__}: GAIN, TAU and DEAD must be "
                                f"{shape[0]} x {shape[1]} (outputs x inputs)")
        cls.CHANNELS = tuple((i, j) for i, row in enumerate(cls.GAIN)
                             for j, k in enumerate(row) if k != 0.0)
        cls.STATES = len(cls.CHANNELS)

    def gain(self, i: int, j: int) -> float:
        """``K_ij`` with the current parameters."""
        return self.GAIN[i][j] * self.gain_factor

    def tau(self, i: int, j: int) -> float:
        """``tau_ij`` [s] with the current parameters."""
        return self.TAU[i][j] * self.tau_factor * self.TIME_UNIT

    def lookback(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for i, j in self.CHANNELS:
            name = self.INPUTS[j][0]
            out[name] = max(out.get(name, 0.0), self.DEAD[i][j] * self.TIME_UNIT)
        return out

    def _deviation(self, j: int, delay: float) -> float:
        name, _unit, start, _d = self.INPUTS[j]
        return self.applied(name, delay) - start

    def rhs(self, x: list[float]) -> list[float]:
        return [(self.gain(i, j) * self._deviation(j, self.DEAD[i][j] * self.TIME_UNIT) - xs)
                / self.tau(i, j) for xs, (i, j) in zip(x, self.CHANNELS, strict=True)]

    def x_guess(self) -> list[float]:
        """The state at rest for the inputs now: the settling starts where it ends."""
        return [self.gain(i, j) * self._deviation(j, 0.0) for i, j in self.CHANNELS]

    def out(self, x: list[float]) -> dict[str, float]:
        y = [start for _n, _u, start, _d in self.OUTPUTS]
        for xs, (i, _j) in zip(x, self.CHANNELS, strict=True):
            y[i] += xs
        return {name: value for (name, _u, _s, _d), value in zip(self.OUTPUTS, y, strict=True)}


def signal_tables(text: str, owner: str = "plant") -> dict[str, tuple[Signal, ...]]:
    """``INPUTS``, ``OUTPUTS``, ``PARAMETERS`` and ``STATE`` from a ``SIGNALS`` table (a line
    each: kind, name, unit, start value, description); a malformed line raises ``TypeError``
    naming it."""
    tables: dict[str, list[Signal]] = {attr: [] for attr in KINDS.values()}
    for line in text.strip().splitlines():
        parts = line.split()
        kind, name, unit, start = (parts + [""] * 4)[:4]
        words = parts[4:]
        try:
            value = float(start)
        except ValueError:
            value = math.nan
        if kind not in KINDS or unit not in UNITS or not words or not math.isfinite(value):
            raise TypeError(f"{owner}.SIGNALS: {line.strip()!r}: expected 'KIND NAME UNIT "
                            f"START DESCRIPTION' (kinds {', '.join(KINDS)}; units "
                            f"{', '.join(UNITS)})")
        tables[KINDS[kind]].append((name, unit, value, " ".join(words)))
    return {attr: tuple(rows) for attr, rows in tables.items()}


def _at(history: list[tuple[float, float]], t: float) -> float:
    """The value applied last at or before ``t`` (a zero-order hold)."""
    value = history[0][1]
    for when, v in history:
        if when <= t + 1e-9:
            value = v
        else:
            break
    return value
