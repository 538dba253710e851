"""The control problem: the plant's manipulated inputs and controlled outputs, by name, in the
plant's own units, with their boxes, the sample time and the normalisation.

A problem may also declare measured disturbances: signals the controller does not move but
measures (an inlet temperature, a feed concentration, a load), each an input of the plant
FMU or one of its tunable parameters, and dead times (``delay``, whole samples) on inputs and
disturbances. The model's inputs are the manipulated inputs then the disturbances
(:attr:`ControlProblem.model_inputs`), each seen ``delay`` samples late.

A problem is declared once, in a TOML file (:func:`controllers.problem_file.load`), and then
travels: ``cosim generate-data`` records it in the data set's sidecar, ``cosim train`` copies
it into the model file (:attr:`controllers.model.GRUModel.problem`), and every later stage
(certificates, the robust MPC, the PI baseline, scenarios, KPIs, figures, campaigns) takes it
from there. Nothing here is specific to one plant: the four-tank benchmark is one problem
file among others (``fmus/fourtank/problem.toml``).

Normalisation (``normalised = (physical − offset) / scale``) follows the box by default,
``offset = (min + max) / 2``, ``scale = (max − min) / 2``: the input box maps to
``‖u‖∞ ≤ 1`` (``eq:input-constraint``) and the output box to ``[−1, 1]``; a signal may declare
its own (an output box much wider than its operating range).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.errors import DesignError, ProblemFileError

__all__ = ["Channel", "ControlProblem", "PILoop", "constraint_names", "output_constraints"]


@dataclass(frozen=True)
class Channel:
    """One manipulated input or controlled output of a :class:`ControlProblem`.

    Attributes
    ----------
    name : str
        The problem's name of the signal: scenario columns (``ref.<name>``), KPIs
        (``iae.<name>``), figures and the model file use it.
    unit : str
        Its unit (the problem's; the plant FMU's may differ, :mod:`cosim.core.binding` converts).
    min, max : float
        The box: saturation of an input (``eq:input-constraint``), the output constraint
        ``min ≤ y ≤ max`` (``eq:output-constraint``).
    variable : str
        The plant FMU's variable (default: ``name``).
    offset, scale : float
        Normalisation ``(value − offset) / scale`` (default: the box's middle and half-width).
    description : str
    hold : (int, int) or None
        Inputs: shortest and longest hold time of the identification excitation [samples].
    levels : (float, float) or None
        Inputs: the range of the excitation's levels (default: the box).
    delay : int
        Inputs and disturbances: the dead time between the signal and its effect on the
        outputs [samples]: the model sees ``signal(k − delay)`` at sample ``k``.
    rate : float or None
        Disturbances: the largest change per sample (problem units), which bounds how far
        the real disturbance moves from the value the MPC holds over its horizon; ``None``:
        the data's largest change per sample. Outputs: the largest change per sample a
        measurement can make; a live run does not use one that moves faster (a spike, a
        transmitter fault); ``None``: no such check.
    preview : bool
        Disturbances: known ahead from the scenario: the robust MPC takes its values to come
        over the inputs' dead time (rather than its last measured value).
    safe : float or None
        Inputs: the value written to a live plant when its measurements stop coming (the
        watchdog of ``cosim run --plant opc.tcp://...``) and when the run stops; ``None``:
        hold the last value written.
    valid : (float, float) or None
        Outputs and disturbances: the range a measurement can have (a transmitter's span,
        wider than the box: the box is a constraint, this is what is plausible); a live run
        does not use a value outside it; ``None``: no such check.
    frozen : int
        Outputs and disturbances: a live run does not use a measurement that stayed the same
        to the bit for this many samples in a row (a frozen transmitter; for noisy signals
        only); 0: no such check.
    max_move : float or None
        Inputs: the largest move per sample (problem units) of every input the controller
        writes, in every mode (the move limit of APC products): a constraint on consecutive
        inputs of the FHOCP and the rate of an input's operator limit
        (:mod:`controllers.operator`); ``None``: the box width (no limit).
    limit_rate : float or None
        Outputs: how fast an active operator limit narrows towards a new one (problem units
        per sample; :mod:`controllers.operator`); ``None``: as fast as the controller's
        present plan allows.
    """

    name: str
    unit: str
    min: float
    max: float
    variable: str = ""
    offset: float = math.nan
    scale: float = math.nan
    description: str = ""
    hold: tuple[int, int] | None = None
    levels: tuple[float, float] | None = None
    delay: int = 0
    rate: float | None = None
    preview: bool = False
    safe: float | None = None
    valid: tuple[float, float] | None = None
    frozen: int = 0
    max_move: float | None = None
    limit_rate: float | None = None

    def __post_init__(self) -> None:
        if not self.variable:
            object.__setattr__(self, "variable", self.name)
        if math.isnan(self.offset):
            object.__setattr__(self, "offset", 0.5 * (self.min + self.max))
        if math.isnan(self.scale):
            object.__setattr__(self, "scale", 0.5 * (self.max - self.min))

    @property
    def bounds(self) -> tuple[float, float]:
        """``(min, max)``."""
        return (self.min, self.max)

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"name": self.name, "unit": self.unit, "min": self.min,
                               "max": self.max}
        if self.variable != self.name:
            doc["variable"] = self.variable
        doc["normalization"] = {"offset": self.offset, "scale": self.scale}
        if self.description:
            doc["description"] = self.description
        if self.hold is not None:
            doc["hold"] = list(self.hold)
        if self.levels is not None:
            doc["levels"] = list(self.levels)
        if self.delay:
            doc["delay"] = self.delay
        if self.rate is not None:
            doc["rate"] = self.rate
        if self.preview:
            doc["preview"] = True
        for key in ("safe", "max_move", "limit_rate"):
            if getattr(self, key) is not None:
                doc[key] = getattr(self, key)
        if self.valid is not None:
            doc["valid"] = list(self.valid)
        if self.frozen:
            doc["frozen"] = self.frozen
        return doc


@dataclass(frozen=True)
class PILoop:
    """One PI loop: output ``y`` controlled by input ``u``, gain ``K`` [u-unit per y-unit],
    integral time ``Ti`` and anti-windup tracking time ``Tt`` [s]."""

    y: str
    u: str
    K: float
    Ti: float
    Tt: float

    def to_dict(self) -> dict[str, Any]:
        return {"output": self.y, "input": self.u, "K": self.K, "Ti": self.Ti, "Tt": self.Tt}


def _column(kind: str, field_name: str, doc: str | None = None) -> Any:
    """A read-only attribute of :class:`ControlProblem`: ``field_name`` of each
    :class:`Channel` of ``kind`` (an attribute, such as ``"inputs"``), as a tuple."""
    return property(lambda problem: tuple(getattr(c, field_name)
                                          for c in getattr(problem, kind)), doc=doc)


@dataclass(frozen=True)
class ControlProblem:
    """Manipulated inputs and controlled outputs with their boxes, sample time and
    normalisation (see the module docstring).

    Attributes
    ----------
    name : str
    Ts : float
        Controller sample time [s].
    inputs, outputs : tuple of Channel
    disturbances : tuple of Channel
        The measured disturbances (the problem file's ``[disturbances]``), empty when none.
    pairings : dict of str to tuple of PILoop
        The PI baseline's loop sets by name (the problem file's ``[pi]``), empty when none.
    pairing : str
        The default of :attr:`pairings` ("" when there are none).
    description : str
    train : dict of str to Any
        ``cosim train``'s options chosen for this plant (the problem file's ``[train]``),
        empty when none; what the command line overrides.
    mpc : dict of str to Any
        The robust MPC's options chosen for this plant (the problem file's ``[mpc]``: keys
        and values as ``--option``'s), empty when none; what a run's options override.
    source : str
        Where the problem was read from (messages only; not compared, not saved).
    """

    name: str
    Ts: float
    inputs: tuple[Channel, ...]
    outputs: tuple[Channel, ...]
    disturbances: tuple[Channel, ...] = ()
    pairings: Mapping[str, tuple[PILoop, ...]] = field(default_factory=dict)
    pairing: str = ""
    description: str = ""
    train: Mapping[str, Any] = field(default_factory=dict)
    mpc: Mapping[str, Any] = field(default_factory=dict)
    source: str = field(default="", compare=False)

    # -- the signals by kind ---------------------------------------------------------------
    @property
    def m(self) -> int:
        """Number of inputs."""
        return len(self.inputs)

    @property
    def p(self) -> int:
        """Number of outputs."""
        return len(self.outputs)

    @property
    def q(self) -> int:
        """Number of measured disturbances."""
        return len(self.disturbances)

    @property
    def model_inputs(self) -> tuple[Channel, ...]:
        """The model's inputs: the manipulated inputs, then the measured disturbances."""
        return (*self.inputs, *self.disturbances)

    @property
    def signals(self) -> tuple[Channel, ...]:
        """Every signal: inputs, outputs, disturbances."""
        return (*self.inputs, *self.outputs, *self.disturbances)

    # one field of each signal of a kind, in the kind's order
    input_names = _column("inputs", "name")
    output_names = _column("outputs", "name")
    disturbance_names = _column("disturbances", "name")
    model_input_names = _column("model_inputs", "name")
    input_units = _column("inputs", "unit")
    output_units = _column("outputs", "unit")
    input_bounds = _column("inputs", "bounds")
    output_bounds = _column("outputs", "bounds")
    delays = _column("model_inputs", "delay", "The dead time of each model input [samples] "
                     "(:attr:`model_inputs`' order).")

    def bounds(self) -> dict[str, tuple[float, float]]:
        """All boxes by signal name (inputs, outputs, disturbances)."""
        return {c.name: c.bounds for c in self.signals}

    def units(self) -> dict[str, str]:
        """All units by signal name (inputs, outputs, disturbances)."""
        return {c.name: c.unit for c in self.signals}

    def channel(self, name: str) -> Channel:
        """The input, output or disturbance ``name``."""
        for c in self.signals:
            if c.name == name:
                return c
        raise KeyError(name)

    def normalization(self) -> dict[str, np.ndarray]:
        """``u_offset, u_scale, y_offset, y_scale`` of the model file (``u``: the model's
        inputs, :attr:`model_inputs`)."""
        return {"u_offset": np.array([c.offset for c in self.model_inputs], dtype=float),
                "u_scale": np.array([c.scale for c in self.model_inputs], dtype=float),
                "y_offset": np.array([c.offset for c in self.outputs], dtype=float),
                "y_scale": np.array([c.scale for c in self.outputs], dtype=float)}

    def describe(self) -> str:
        """One line: ``name: F [L/min], Tc [K] -> CA [mol/L], T [K] at Ts = 15 s`` (and
        ``; measured: Tin [K]``, ``F [L/min] +2 samples`` for disturbances and dead times)."""
        def sig(cs: tuple[Channel, ...]) -> str:
            return ", ".join(f"{c.name} [{c.unit}]" + (f" +{c.delay} samples" if c.delay else "")
                             for c in cs)
        measured = f"; measured: {sig(self.disturbances)}" if self.disturbances else ""
        return (f"{self.name}: {sig(self.inputs)} -> {sig(self.outputs)} at Ts = "
                f"{self.Ts:g} s{measured}")

    # -- (de)serialisation (the model file's and the data sidecar's "problem") --------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON form (read back by :func:`controllers.problem_file.problem_from_dict`)."""
        doc: dict[str, Any] = {"name": self.name, "Ts": self.Ts}
        if self.description:
            doc["description"] = self.description
        doc["inputs"] = [c.to_dict() for c in self.inputs]
        doc["outputs"] = [c.to_dict() for c in self.outputs]
        if self.disturbances:
            doc["disturbances"] = [c.to_dict() for c in self.disturbances]
        if self.pairings:
            doc["pi"] = {"pairing": self.pairing,
                         "pairings": {k: [lp.to_dict() for lp in v]
                                      for k, v in self.pairings.items()}}
        for table in ("train", "mpc"):
            if getattr(self, table):
                doc[table] = dict(getattr(self, table))
        return doc

    def differences(self, other: ControlProblem) -> list[str]:
        """What differs between two problems (empty when they are the same), one short
        phrase each: used to refuse a ``--problem`` that contradicts a model file."""
        out = []
        if self.name != other.name:
            out.append(f"name {self.name!r} vs {other.name!r}")
        if not math.isclose(self.Ts, other.Ts, rel_tol=1e-12):
            out.append(f"Ts {self.Ts:g} vs {other.Ts:g} s")
        for kind, a, b in (("inputs", self.inputs, other.inputs),
                           ("outputs", self.outputs, other.outputs),
                           ("disturbances", self.disturbances, other.disturbances)):
            if [c.name for c in a] != [c.name for c in b]:
                out.append(f"{kind} {[c.name for c in a]} vs {[c.name for c in b]}")
                continue
            for ca, cb in zip(a, b, strict=True):
                for key in ("unit", "min", "max", "variable", "offset", "scale", "delay"):
                    va, vb = getattr(ca, key), getattr(cb, key)
                    same = (math.isclose(va, vb, rel_tol=1e-12, abs_tol=0.0)
                            if isinstance(va, float) else va == vb)
                    if not same:
                        out.append(f"{ca.name}.{key} {va!r} vs {vb!r}")
        return out


def output_constraints(model: Any, problem: ControlProblem | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """``(L, h)`` of ``eq:output-constraint`` (``L y ≤ h``) in the model's normalised units.

    For each model output ``j`` (matched by name with the problem's outputs; default
    ``model.problem``) two rows: ``+y_j ≤ (max − offset)/scale`` and
    ``−y_j ≤ −(min − offset)/scale``; a negative scale swaps the two bounds.
    """
    problem = _problem_of(model, problem)
    names = list(model.output_names)
    rows, rhs = [], []
    bounds = {c.name: c.bounds for c in problem.outputs}
    for j, name in enumerate(names):
        if name not in bounds:
            raise DesignError(f"model output {name!r} has no bounds in the control problem "
                              f"(outputs {', '.join(problem.output_names)})")
        lo, hi = bounds[name]
        off, sc = float(model.y_offset[j]), float(model.y_scale[j])
        nlo, nhi = sorted(((lo - off) / sc, (hi - off) / sc))
        e = np.zeros(len(names))
        e[j] = 1.0
        rows += [e, -e]
        rhs += [nhi, -nlo]
    return np.array(rows), np.array(rhs)


def constraint_names(model: Any, problem: ControlProblem | None = None) -> list[str]:
    """Readable names of the rows of :func:`output_constraints` (e.g. ``h1 <= 2 m``)."""
    problem = _problem_of(model, problem)
    names = []
    for j, name in enumerate(model.output_names):
        c = problem.channel(name)
        lo, hi = c.min, c.max
        if model.y_scale[j] < 0:
            lo, hi = hi, lo
        names += [f"{name} <= {hi:g} {c.unit}", f"{name} >= {lo:g} {c.unit}"]
    return names


def _problem_of(model: Any, problem: ControlProblem | None) -> ControlProblem:
    problem = problem if problem is not None else getattr(model, "problem", None)
    if problem is None:
        source = getattr(model, "source", None) or "the model"
        raise ProblemFileError(f"{source}: the model file has no control problem (train it "
                               "with 'cosim train --problem', or give the problem)")
    return problem
