"""Plants and a controller that are not the four tanks: the co-simulation core on other
control problems (other names, units, numbers of inputs and outputs).

* :class:`IntegralController`: a tiny sampled controller for any ``m`` inputs and ``p``
  outputs, ``u_k = sat(u_k-1 + g B⁺ (r_k − y_k))`` in the problem's boxes; its subclasses
  :class:`HeaterController` (m = 1, p = 1), :class:`MixerController` (m = 3, p = 2) and
  :class:`TripleController` (m = 2, p = 3) are constructible without arguments
  (``--controller tests.cosim.other_plants:HeaterController``, from the repository root).
* :class:`FirstOrderPlant`: a plain :class:`~cosim.core.component.Component` plant,
  ``τ y' = y0 + B u + D d − y`` with disturbance inputs ``d`` a scenario may set.
* :data:`MIXER_FMU`: the mixer as a pythonfmu FMU (FMI 2.0) with a tunable parameter
  ``loss`` (:func:`build_mixer_fmu`), for campaigns, whose plant is a file.
* :func:`keep_figures`: the matplotlib figures a test draws, to look at their panels.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.core import plots
from cosim.core.component import Component, Signal


@dataclass(frozen=True)
class Problem:
    """Signals ``(name, unit, min, max)``, the static gain ``B`` (p × m) and the rest."""

    outputs: tuple[tuple[str, str, float, float], ...]
    inputs: tuple[tuple[str, str, float, float], ...]
    B: tuple[tuple[float, ...], ...]
    y0: tuple[float, ...]
    disturbances: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    Ts: float = 10.0

    @property
    def output_names(self) -> list[str]:
        return [s[0] for s in self.outputs]

    @property
    def input_names(self) -> list[str]:
        return [s[0] for s in self.inputs]

    def units(self) -> dict[str, str]:
        return {s[0]: s[1] for s in (*self.outputs, *self.inputs)}

    def bounds(self) -> dict[str, tuple[float, float]]:
        return {s[0]: (s[2], s[3]) for s in (*self.inputs, *self.outputs)}


#: m = 1, p = 1: an electric heater, power [kW] → temperature [K]; a heat loss [kW].
HEATER = Problem(outputs=(("temp", "K", 290.0, 350.0),), inputs=(("power", "kW", 0.0, 5.0),),
                 B=((10.0,),), y0=(293.0,), disturbances={"q_loss": (-10.0,)})
#: m = 3, p = 2: a mixing tank, hot/cold water [L/min] and acid [mL/min] → temperature
#: [degC] and concentration [mol/L].
MIXER = Problem(outputs=(("T", "degC", 10.0, 80.0), ("conc", "mol/L", 0.0, 1.2)),
                inputs=(("F_hot", "L/min", 0.0, 10.0), ("F_cold", "L/min", 0.0, 10.0),
                        ("F_acid", "mL/min", 0.0, 50.0)),
                B=((6.0, -1.0, 0.0), (0.01, 0.0, 0.02)), y0=(20.0, 0.0),
                disturbances={"T_in": (0.5, 0.0)})
#: m = 2, p = 3: a reactor, feed [m3/h] and heating [kW] → level [m], temperature [K],
#: pH (dimensionless).
TRIPLE = Problem(outputs=(("level", "m", 0.0, 3.0), ("temp", "K", 280.0, 380.0),
                          ("pH", "", 0.0, 14.0)),
                 inputs=(("feed", "m3/h", 0.0, 4.0), ("heat", "kW", 0.0, 20.0)),
                 B=((0.5, 0.0), (-2.0, 4.0), (0.3, 0.0)), y0=(0.2, 300.0, 6.0))


class IntegralController(Component):
    """``u_k = sat(u_{k−1} + gain · B⁺ (r_k − y_k))``, started at the middle of the input
    boxes; measures every output, takes a set-point for each (``ref.<output>``)."""

    direct_feedthrough = True

    def __init__(self, problem: Problem, gain: float = 0.3, name: str = "integral") -> None:
        self.name = name
        self.problem = problem
        units = problem.units()
        self.inputs = tuple(Signal(o, units[o]) for o in problem.output_names) + tuple(
            Signal(f"ref.{o}", units[o]) for o in problem.output_names)
        self.outputs = tuple(Signal(u, units[u]) for u in problem.input_names)
        self.bounds = problem.bounds()
        self.sample_time = problem.Ts
        self.K = float(gain) * np.linalg.pinv(np.array(problem.B, dtype=float))
        self.lo = np.array([s[2] for s in problem.inputs])
        self.hi = np.array([s[3] for s in problem.inputs])
        self.u = 0.5 * (self.lo + self.hi)
        self._in: dict[str, float] = {}
        self.steps = 0

    def setup(self, t0: float) -> None:
        self.u = 0.5 * (self.lo + self.hi)
        self.steps = 0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._in.update(values)

    def step(self, t: float, dt: float) -> None:
        names = self.problem.output_names
        e = np.array([self._in[f"ref.{o}"] - self._in[o] for o in names])
        self.u = np.clip(self.u + self.K @ e, self.lo, self.hi)
        self.steps += 1

    def get_outputs(self) -> dict[str, float]:
        return {u: float(v) for u, v in zip(self.problem.input_names, self.u, strict=True)}

    def diagnostics(self) -> dict[str, float]:
        return {"saturated": float(np.count_nonzero((self.u <= self.lo) | (self.u >= self.hi)))}

    def summary(self) -> dict:
        return {"steps": self.steps}


class HeaterController(IntegralController):
    """:class:`IntegralController` of :data:`HEATER` (m = 1, p = 1)."""

    def __init__(self, gain: float = 0.3) -> None:
        super().__init__(HEATER, gain)


class MixerController(IntegralController):
    """:class:`IntegralController` of :data:`MIXER` (m = 3, p = 2)."""

    def __init__(self, gain: float = 0.3) -> None:
        super().__init__(MIXER, gain)


class TripleController(IntegralController):
    """:class:`IntegralController` of :data:`TRIPLE` (m = 2, p = 3)."""

    def __init__(self, gain: float = 0.3) -> None:
        super().__init__(TRIPLE, gain)


class FirstOrderPlant(Component):
    """``τ y' = y0 + B u + D d − y`` (exact for inputs held over a step), ``y(0) = y0``;
    the manipulated inputs and the disturbances ``d`` are its inputs."""

    def __init__(self, problem: Problem, tau: float = 50.0, name: str = "plant") -> None:
        self.name = name
        self.problem = problem
        units = problem.units()
        self.inputs = tuple(Signal(u, units[u]) for u in problem.input_names) + tuple(
            Signal(d) for d in problem.disturbances)
        self.outputs = tuple(Signal(o, units[o]) for o in problem.output_names)
        self.tau = tau
        self.B = np.array(problem.B, dtype=float)
        self.y0 = np.array(problem.y0, dtype=float)
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        self.y = self.y0.copy()
        self.u = dict.fromkeys(self.problem.input_names, 0.0)
        self.d = dict.fromkeys(self.problem.disturbances, 0.0)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        for k, v in values.items():
            (self.u if k in self.u else self.d)[k] = float(v)

    def step(self, t: float, dt: float) -> None:
        u = np.array([self.u[n] for n in self.problem.input_names])
        target = self.y0 + self.B @ u
        for name, effect in self.problem.disturbances.items():
            target = target + np.asarray(effect) * self.d[name]
        self.y = target + (self.y - target) * np.exp(-dt / self.tau)

    def get_outputs(self) -> dict[str, float]:
        return {o: float(v) for o, v in zip(self.problem.output_names, self.y, strict=True)}


#: The mixer of :data:`MIXER` as a pythonfmu FMU: inputs F_hot, F_cold, F_acid, outputs T,
#: conc, a tunable parameter ``loss`` [degC] that lowers the temperature's steady state.
MIXER_FMU = '''
import math
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Mixer(Fmi2Slave):
    author = "tests"
    description = "mixing tank: hot, cold water and acid in; temperature, concentration out"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.F_hot = self.F_cold = self.F_acid = 0.0
        self.T, self.conc, self.loss = 20.0, 0.0, 0.0
        for name in ("F_hot", "F_cold", "F_acid"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("T", "conc"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        self.register_variable(Real("loss", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        T_ss = 20.0 + 6.0 * self.F_hot - 1.0 * self.F_cold - self.loss
        c_ss = 0.01 * self.F_hot + 0.02 * self.F_acid
        a = math.exp(-step_size / 50.0)
        self.T = T_ss + (self.T - T_ss) * a
        self.conc = c_ss + (self.conc - c_ss) * a
        return True
'''


def build_mixer_fmu(dest: Path) -> Path:
    """Build :data:`MIXER_FMU` into ``dest`` (``Mixer.fmu``) and return its path."""
    from pythonfmu.builder import FmuBuilder

    dest.mkdir(parents=True, exist_ok=True)
    script = dest / "mixer.py"
    script.write_text(MIXER_FMU)
    return Path(FmuBuilder.build_FMU(script, dest=dest))



def keep_figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The figures drawn from now on (still saved)."""
    figures: list[Any] = []
    save = plots.save

    def keep(fig: Any, *args: Any, **kwargs: Any) -> None:
        figures.append(fig)
        save(fig, *args, **kwargs)

    monkeypatch.setattr(plots, "save", keep)
    return figures
