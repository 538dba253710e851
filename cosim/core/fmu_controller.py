"""A controller FMU as the run's controller: ``cosim run SCENARIO --controller Controller.fmu``.

:class:`FmuController` steps a Co-Simulation controller FMU (one that ``cosim export-fmu``
writes, or any FMU with the same conventions) where the master steps a controller, in the
order a controller FMU is meant to run: set the measured outputs ``y_k``, the set-points
``ref.<output>`` and the measured disturbances ``dist.<name>``, ``doStep(t_k, Ts)``, read
the inputs ``u_k`` to apply to the plant over ``[t_k, t_k+1)`` (docs:
guide/controller-fmu.md). Its outputs named ``status``,
``fallback``, ``iterations``, ``pred.<output>`` and ``target.<output>`` are diagnostics
(recorded, not wired to the plant); every other output is an input of the plant, as a
controller's are. Its sample time is the FMU's default experiment step size; its parameters
(``offset_filter``, the weights ``R.<input>``, ``du_weight.<input>``,
``offset_weight.<output>``, ``setpoint_rate``) are options of the component, a family of
them also in the robust MPC's form (``R=0.02``: every entry; ``offset_weight={"h1": 1e3}``:
by signal), each checked against the box its modelDescription declares before anything
runs. ``cosim run`` and campaigns step it in a worker process of its own
(:class:`cosim.core.isolated.IsolatedFmuController`); this class runs it in this process
(a benchmark's baseline).

A live run does not step its controller at a sample without a fresh measurement (the Python
controller's observer does not advance); an FMU's clock must, so the samples the master
skipped are stepped first with the measured outputs not finite, on which an exported
controller holds its inputs and does not advance its observer (docs:
guide/controller-fmu.md): the same controller state as the Python controller's.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cosim.core.component import Capability, Setting
from cosim.core.errors import CosimError
from cosim.core.fmu import FmuComponent
from cosim.core.fmu_archive import why_not_valid
from cosim.core.varmap import variable_unit

__all__ = ["DIAGNOSTIC_OUTPUTS", "FmuController"]

#: Outputs of a controller FMU that are diagnostics, not plant inputs (and ``pred.*``,
#: ``target.*``).
DIAGNOSTIC_OUTPUTS = frozenset({"status", "fallback", "iterations"})


def _diagnostic(name: str) -> bool:
    return (name in DIAGNOSTIC_OUTPUTS or name == "op.refused"
            or name.startswith(("pred.", "target.", "computed.")))


class FmuController(FmuComponent):
    """A controller FMU (module docstring).

    Parameters
    ----------
    path : str or Path
        The controller FMU (FMI 2.0 or 3.0 Co-Simulation).
    name : str
        Component name.
    **parameters
        Values of its parameters, set before its initialisation (``cosim run --controller
        Controller.fmu --option offset_filter=0.5``); a family ``key.<signal>`` also as
        ``key`` with one number (every signal) or an object by signal name
        (``--option 'offset_weight={"h1": 1000}'``).
    """

    direct_feedthrough = True
    #: its measured disturbances' defaults are its inputs' start values; it names the plant
    #: variables it exchanges (the record ``cosim export-fmu`` writes); its tunable
    #: parameters are its settings
    capabilities = frozenset({Capability.DISTURBANCES, Capability.PLANT_SIGNALS,
                              Capability.SETTINGS})

    def __init__(self, path: str | Path, name: str = "ctrl", **parameters: Any) -> None:
        super().__init__(path, name=name, interface="cs")
        parameters = self._expand(parameters)
        unknown = sorted(set(parameters) - set(self.parameters))
        if unknown:
            raise CosimError(f"{self.path}: {unknown[0]!r} is not a parameter of the "
                             f"controller FMU (parameters: {', '.join(self.parameters)})")
        for key, value in parameters.items():
            self._check_parameter(key, value)
        self.start_values = {k: float(v) for k, v in parameters.items()}
        self._diag_names = [s.name for s in self.outputs if _diagnostic(s.name)]
        self.outputs = tuple(s for s in self.outputs if not _diagnostic(s.name))
        self._u_names = [s.name for s in self.outputs]
        experiment = self.md.defaultExperiment
        step = getattr(experiment, "stepSize", None) if experiment is not None else None
        if step is None:
            raise CosimError(f"{self.path}: a controller FMU needs its sample time as the "
                             "default experiment's stepSize")
        self.sample_time = float(step)
        self.bounds = {v.name: (float(v.min), float(v.max))
                       for v in self.md.modelVariables
                       if v.causality == "output" and not _diagnostic(v.name)
                       and v.min is not None and v.max is not None}
        #: a measured disturbance's value when the scenario has no ``dist.<name>`` column:
        #: its input's start value (the middle of its box), as the Python controller's
        self.disturbance_defaults = {
            v.name[len("dist."):]: float(v.start) for v in self.md.modelVariables
            if v.causality == "input" and v.name.startswith("dist.") and v.start is not None}
        self._diag: dict[str, float] = {}
        #: its operator settings (inputs ``op.*``: set through :meth:`set`, not wired)
        self._op_names = [s.name for s in self.inputs if s.name.startswith("op.")]
        self.inputs = tuple(s for s in self.inputs if not s.name.startswith("op."))
        if self._op_names:
            self.capabilities = type(self).capabilities | {Capability.OPERATOR}
        #: the measured outputs among its inputs (not a set-point, not a disturbance)
        self._measured = [s.name for s in self.inputs
                          if not s.name.startswith(("ref.", "dist."))]
        self._given: dict[str, float] = {}
        self._served = _Served()

    def _check_parameter(self, key: str, value: Any) -> None:
        """A finite number inside the box the modelDescription declares for ``key``, else
        :class:`CosimError` (bad input: nothing has run)."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CosimError(f"{self.path}: parameter {key}={value!r}: expected a number")
        why = why_not_valid(self.variable_of(key), value)
        if why:
            raise CosimError(f"{self.path}: parameter {key}={value!r}: {why} (the FMU's "
                             "modelDescription)")

    def _expand(self, given: dict[str, Any]) -> dict[str, Any]:
        """``key=value`` for a family of parameters ``key.<signal>`` (the robust MPC's option
        form: one number for every signal, or an object by signal name) as its members."""
        out: dict[str, Any] = {}
        for key, value in given.items():
            family = [p for p in self.parameters if p.startswith(key + ".")]
            if key in self.parameters or not family:
                out[key] = value
            elif isinstance(value, Mapping):
                for signal, v in value.items():
                    if f"{key}.{signal}" not in family:
                        raise CosimError(f"{self.path}: option {key}: {signal!r} is not one of "
                                         f"its signals ({', '.join(family)})")
                    out[f"{key}.{signal}"] = v
            else:
                out.update(dict.fromkeys(family, value))
        return out

    def plant_signals(self) -> list[Any]:
        """What the FMU exchanges with the plant as :class:`cosim.core.binding.Wanted`: its
        measured outputs, inputs to apply and measured disturbances, each with the plant
        variable its modelDescription records (:func:`cosim.core.fmu_archive.
        plant_variables`, ``cosim export-fmu``'s) and its unit; empty for an FMU without that
        record (its signals are then the plant's variables of their own names)."""
        from cosim.core.binding import Wanted
        from cosim.core.fmu_archive import plant_variables
        from cosim.core.varmap import variable_unit

        named = plant_variables(self.path)
        if not named:
            return []
        where = f"{self.path.name} (the plant variables it records)"
        out = []
        for v in self.md.modelVariables:
            if v.name not in named or v.causality not in ("input", "output"):
                continue
            role = ("disturbance" if v.name.startswith("dist.")
                    else "output" if v.causality == "input" else "input")
            out.append(Wanted(v.name.removeprefix("dist."), named[v.name],
                              variable_unit(v) or "", role, where))
        return out

    def settings(self) -> dict[str, Setting]:
        """Its tunable parameters, with the range its modelDescription declares and their
        values when the run starts."""
        out = {}
        for name in self.tunables:
            v = self.variable_of(name)
            low = float(v.min) if v.min is not None else -math.inf
            high = float(v.max) if v.max is not None else math.inf
            start = self.start_values.get(name, float(v.start) if v.start is not None
                                          else math.nan)
            out[name] = Setting(name, low, high, v.description or "", float(start))
        for name in self._op_names:   # the operator's (OPERATOR)
            v = self.variable_of(name)
            low = float(v.min) if v.min is not None else -math.inf
            high = float(v.max) if v.max is not None else math.inf
            start = float(v.start) if v.start is not None else math.nan
            unit = variable_unit(v) or ""
            out[name] = Setting(name, low, high, v.description or "", start,
                                "" if unit == "1" else unit, role="operator")
        return out

    def set(self, name: str, value: float) -> str:
        """Tunable parameter ``name`` set from the next step on (checked against its box
        first); the FMU re-derives what depends on it itself. An operator setting (its
        input ``op.*``) the FMU refuses is kept as it was (its output ``op.refused``
        counts it): :class:`CosimError`."""
        if name in self._op_names:
            before = super().get_outputs().get("op.refused", 0.0)
            self.set_parameter(name, float(value))
            if super().get_outputs().get("op.refused", 0.0) > before:
                raise CosimError(f"{self.path.name}: {name}={value!r}: refused by the "
                                 "controller (kept as it was: an operator limit that crosses "
                                 "the other, or leaves no admissible steady output)")
            return f"{name} = {float(value):g}"
        if name not in self.tunables:
            raise CosimError(f"{self.path}: no setting '{name}' (settings: "
                             f"{', '.join(self.tunables) or 'none'})")
        self._check_parameter(name, value)
        self.set_parameter(name, float(value))
        return ""

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Load and initialise the FMU (again after a run: a fresh instance)."""
        if self._fmu is not None:
            self.terminate()
        self._given.clear()
        self._served = _Served()
        super().setup(t0, stop_time)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._given.update(values)
        super().set_inputs(values)

    def step(self, t: float, dt: float) -> None:
        """``doStep(t, dt)``, after the samples the master skipped since the last step
        (module docstring) were stepped with the measured outputs not finite."""
        skipped = self._skipped(t, dt)
        if skipped:
            now = {n: self._given[n] for n in self._measured if n in self._given}
            super().set_inputs(dict.fromkeys(self._measured, math.nan))
            for s in skipped:
                super().step(s, dt)
            super().set_inputs(now)
        super().step(t, dt)
        self._served.stepped(t)

    def _skipped(self, t: float, dt: float) -> list[float]:
        """The sample instants from the FMU's time up to ``t`` (none when ``t`` is its time,
        or not a whole number of samples past it: the FMU then answers for itself)."""
        k = round((t - self._t) / dt) if dt > 0 else 0
        if k < 1 or abs(t - self._t - k * dt) > 1e-9 * max(dt, abs(t)):
            return []
        return [t - (k - i) * dt for i in range(k)]

    def get_outputs(self) -> dict[str, float]:
        """The inputs to apply (the diagnostics are kept for :meth:`diagnostics`)."""
        values = super().get_outputs()
        self._diag = {n: values[n] for n in self._diag_names}
        self._served.read(self._diag)
        return {n: values[n] for n in self._u_names}

    def diagnostics(self) -> dict[str, float]:
        return dict(self._diag)

    def summary(self) -> dict:
        return {"controller": "fmu", "fmu": str(self.path),
                "description": self.md.description or "", "parameters": dict(self.start_values),
                **self._served.summary()}


class _Served:
    """The steps an exported robust MPC fell back on its candidate plan (its ``fallback``
    output), counted as the Python controller counts them (``controllers.mpc``: the summary's
    ``fallbacks`` and ``shortfall``, which the run's verdict reads)."""

    def __init__(self) -> None:
        self.steps = self.fallbacks = 0
        self.first: float | None = None
        self.codes: Counter[int] = Counter()
        self._due: float | None = None

    def stepped(self, t: float) -> None:
        """A step at ``t`` was taken; its outputs are read next."""
        self.steps += 1
        self._due = t

    def read(self, diagnostics: Mapping[str, float]) -> None:
        """The outputs after a step: a fallback counted once, with its status code."""
        t, self._due = self._due, None
        if t is None or not diagnostics.get("fallback", 0.0) >= 0.5:
            return
        self.fallbacks += 1
        self.codes[int(diagnostics.get("status", -1))] += 1
        if self.first is None:
            self.first = t

    def summary(self) -> dict[str, Any]:
        """``fallbacks`` and ``shortfall`` (none when it never fell back)."""
        if not self.fallbacks:
            return {}
        why = ", ".join(f"status code {c} {n}" for c, n in self.codes.most_common(3))
        return {"fallbacks": self.fallbacks,
                "shortfall": {"steps": self.fallbacks, "of": self.steps,
                              "what": "fell back on the candidate plan", "why": why,
                              "first_time": self.first}}
