"""The one interface for everything the master steps: plants, controllers, sensors.

Components are systems wired by signal name (python-control style). The master calls, in
order: :meth:`Component.expect_setpoints` (controllers), :meth:`Component.setup`, then per
communication step ``set_inputs`` / ``step`` / ``get_outputs``, and finally
:meth:`Component.terminate`.

Timing convention (zero-order hold, Gauss-Seidel within a step):

* A component with ``direct_feedthrough = False`` (a plant) exposes in ``get_outputs()`` the
  values at the current time ``t``; ``step(t, dt)`` advances it to ``t + dt`` with its inputs
  held constant.
* A component with ``direct_feedthrough = True`` (a sampled controller, a sensor model)
  computes, in ``step(t, dt)``, outputs from the inputs set at ``t``; these outputs are held
  over ``[t, t + dt)``.

What a component offers beyond stepping it **declares** in :attr:`Component.capabilities`
(:class:`Capability`): the run reads the declaration once when it wires the loop, and the
isolation proxy (:mod:`cosim.core.isolated`) forwards exactly what is declared to the worker
process that runs the component. The base class gives every capability's attributes and
methods a neutral default, so nothing is probed for.
"""

from __future__ import annotations

import bisect
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["Capability", "Component", "Prediction", "Schedule", "Setting", "Signal"]


@dataclass(frozen=True)
class Signal:
    """A named scalar signal with its unit (``""`` when dimensionless)."""

    name: str
    unit: str = ""
    description: str = ""


class Capability(StrEnum):
    """What a component may offer beyond stepping (:attr:`Component.capabilities`).

    ``TUNABLE``
        A plant whose parameters (:attr:`Component.tunables`, and any other
        :meth:`Component.settable` at the start) a scenario sets: :meth:`Component.
        set_parameter`.
    ``SIGNAL_CHECK``
        A plant that checks the signals a run wires to it before the first step:
        :meth:`Component.check_signals`.
    ``SETPOINTS``
        A controller that designs for the run's set-points: :meth:`Component.
        expect_setpoints`.
    ``DISTURBANCES``
        A controller measuring disturbances (inputs ``dist.<name>``) with nominal values
        for a run that does not set them: :attr:`Component.disturbance_defaults`.
    ``PREVIEW``
        A controller told measured disturbances ahead (:attr:`Component.previewed`): the
        run hands it their :class:`Schedule` (:meth:`Component.set_schedule`).
    ``PLANT_SIGNALS``
        A controller that names the plant variables it exchanges:
        :meth:`Component.plant_signals`.
    ``NOTICE``
        A controller with one line to show before the run: :attr:`Component.notice`.
    ``SETTINGS``
        Settings that may change between steps, by name (:meth:`Component.settings`,
        :meth:`Component.set`): weights, limits, modes.
    ``ESTIMATE``
        A controller with a state estimate whose start may be given
        (:meth:`Component.set_initial_estimate`) and which says where it stands
        (:meth:`Component.estimate`): the campaigns' theorem checks on a model plant.
    ``OPERATOR``
        A controller an operator runs (:mod:`controllers.operator`): its
        :meth:`Component.settings` include the operator's (``op.mode``, ``op.service.<u>``,
        ``op.manual.<u>``, ``op.control.<y>``, ``op.min.<s>``, ``op.max.<s>``; role
        ``"operator"``), which :meth:`Component.set` takes like any; its outputs are the
        inputs the plant gets, its diagnostics ``computed.<input>`` what it computed (in
        manual: in shadow), and :meth:`Component.operator_status` what it predicts.
    ``PREDICTION``
        A predictive controller that says what it plans at its last step
        (:meth:`Component.prediction`): the outputs it predicts over its horizon, the inputs
        it plans and the constraints its plan keeps (a live page of the run, :mod:`cosim.hmi`).
    """

    TUNABLE = "tunable"
    SIGNAL_CHECK = "signal-check"
    SETPOINTS = "setpoints"
    DISTURBANCES = "disturbances"
    PREVIEW = "preview"
    PLANT_SIGNALS = "plant-signals"
    NOTICE = "notice"
    SETTINGS = "settings"
    ESTIMATE = "estimate"
    OPERATOR = "operator"
    PREDICTION = "prediction"


@dataclass(frozen=True)
class Schedule:
    """A piecewise-constant signal as data (picklable: it travels to a worker process):
    ``times[i]`` the instants its value becomes ``values[i]``, ``default`` before the first.
    ``schedule(t)`` is its value at ``t`` (a row holds until the next)."""

    times: tuple[float, ...]
    values: tuple[float, ...]
    default: float

    def __call__(self, t: float) -> float:
        i = bisect.bisect_right(self.times, t + 1e-9 * max(1.0, abs(t)))
        return self.values[i - 1] if i else float(self.default)


@dataclass(frozen=True)
class Setting:
    """A setting a component changes between steps (:meth:`Component.set`): its ``name``,
    the range a value must lie in, its ``unit``, what it is (``description``), its value
    when the run starts (``start``) and who may change it (``role``: ``"engineer"``, the
    design's weights and gains; ``"operator"``, the operator's ``op.*`` settings, which an
    engineer may change too)."""

    name: str
    low: float
    high: float
    description: str = ""
    start: float = float("nan")
    unit: str = ""
    role: str = "engineer"


@dataclass(frozen=True)
class Prediction:
    """What a predictive controller plans at its last step (:meth:`Component.prediction`),
    in the problem's units; picklable (it travels from a worker process).

    Attributes
    ----------
    step : float
        Seconds between two predicted samples (the controller's sample time); sample ``i``
        of the plan is ``i * step`` after the step's instant.
    outputs : mapping of str to tuple of float
        Each controlled output's predicted values, samples ``0 … N``.
    inputs : mapping of str to tuple of float
        Each input's planned values, samples ``0 … N−1``.
    low, high : mapping of str to tuple of float
        Each output's constraint as the plan keeps it at samples ``0 … N−1`` (the robust
        MPC's tightened box; ``nan`` where a side has none).
    fallback : bool
        The plan is not the last solve's answer (the controller fell back on an earlier
        plan); ``outputs`` then show the solve it did not apply.
    """

    step: float
    outputs: Mapping[str, tuple[float, ...]]
    inputs: Mapping[str, tuple[float, ...]]
    low: Mapping[str, tuple[float, ...]]
    high: Mapping[str, tuple[float, ...]]
    fallback: bool = False


class Component(ABC):
    """Base class of every block the co-simulation master steps.

    Attributes
    ----------
    name : str
        Instance name, used as the prefix of recorded signals.
    inputs, outputs : tuple of Signal
        Declared signals; the master wires them by name.
    direct_feedthrough : bool
        Whether outputs over ``[t, t+dt)`` depend on inputs at ``t`` (controllers, sensors).
    sample_time : float or None
        Natural sample time [s] (a controller's Ts); the master's default communication step.
    bounds : dict of (float, float)
        Box constraints by signal name, for KPIs (violations) and figures; may name signals
        the component does not own (a controller declares the plant outputs it constrains).
    timing_diagnostics : frozenset of str
        Diagnostics that are wall-clock measurements (e.g. ``solve_ms``). The master records
        them apart (``timings.csv``) so that ``results.csv`` stays reproducible byte for byte.
    isolated : bool
        Whether the component runs its steps in a worker process whose every request its
        ``timeout`` attribute bounds (:mod:`cosim.core.isolated`): the master hands such a
        controller the run's step timeout instead of arming ``SIGALRM``.
    capabilities : frozenset of Capability
        What it offers beyond stepping (:class:`Capability`); the attributes below belong
        to one each and are neutral by default.
    tunables : tuple of str
        (``TUNABLE``) Parameters a run may set while it runs.
    disturbance_defaults : mapping of str to float
        (``DISTURBANCES``) A measured disturbance's value when the scenario does not set it.
    previewed : tuple of str
        (``PREVIEW``) The measured disturbances it is told ahead.
    notice : str or None
        (``NOTICE``) One line to show before the run.
    problem : object or None
        The control problem it is designed for (a :class:`controllers.problem.
        ControlProblem`), when it has one.
    """

    name: str = "component"
    inputs: tuple[Signal, ...] = ()
    outputs: tuple[Signal, ...] = ()
    direct_feedthrough: bool = False
    sample_time: float | None = None
    bounds: dict[str, tuple[float, float]] = {}  # noqa: RUF012 - read-only class default
    timing_diagnostics: frozenset[str] = frozenset()
    isolated: bool = False
    capabilities: frozenset[Capability] = frozenset()
    tunables: tuple[str, ...] = ()
    disturbance_defaults: Mapping[str, float] = {}
    previewed: tuple[str, ...] = ()
    notice: str | None = None
    problem: Any = None

    @property
    def where(self) -> str:
        """How messages name the component (a plant FMU: its file)."""
        return self.name

    def setup(self, t0: float) -> None:  # noqa: B027 - optional hook
        """Prepare for a run starting at ``t0`` (instantiate, initialise)."""

    @abstractmethod
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set input signals by name (a subset of :attr:`inputs` is allowed)."""

    @abstractmethod
    def step(self, t: float, dt: float) -> None:
        """Advance over ``[t, t + dt)`` (see the module docstring for timing)."""

    @abstractmethod
    def get_outputs(self) -> dict[str, float]:
        """Current output values by name."""

    def diagnostics(self) -> dict[str, float]:
        """Per-step diagnostics to record (solver statistics, estimates); empty by default."""
        return {}

    def summary(self) -> dict:
        """Whole-run statistics for ``summary.json``; empty by default."""
        return {}

    def terminate(self) -> None:  # noqa: B027 - optional hook
        """Release resources. Must be safe to call more than once."""

    # -- capabilities (neutral defaults) -----------------------------------------------------
    def settable(self, at_start: bool = False) -> set[str]:
        """Names a scenario may set: the inputs, and (``TUNABLE``) the parameters."""
        return {s.name for s in self.inputs} | set(self.tunables)

    def set_parameter(self, name: str, value: float) -> None:
        """(``TUNABLE``) Set a parameter (or an input) while the run runs."""
        raise CosimError(f"{self.where}: no parameter '{name}'")

    def check_signals(self, inputs: list[str], outputs: list[str],  # noqa: B027
                      units: Mapping[str, str] | None = None) -> None:
        """(``SIGNAL_CHECK``) Check the signals a run wires to this plant."""

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:  # noqa: B027
        """(``SETPOINTS``) Before :meth:`setup`: the set-points the run will request, in
        order (each by output name; :meth:`cosim.core.scenario.Scenario.setpoints`), so that
        a controller can design for them (the robust MPC decides there whether it runs
        certified)."""

    def set_schedule(self, schedules: Mapping[str, Schedule] | None) -> None:  # noqa: B027
        """(``PREVIEW``) After :meth:`setup`: the values to come of :attr:`previewed`, by
        name."""

    def plant_signals(self) -> Sequence[Any] | None:
        """(``PLANT_SIGNALS``) What it exchanges with the plant, by the plant variables it
        records (:class:`cosim.core.binding.Wanted`); ``None`` when it does not say."""
        return None

    def settings(self) -> Mapping[str, Setting]:
        """(``SETTINGS``) The settings :meth:`set` takes, by name."""
        return {}

    def set_initial_estimate(self, x0: Sequence[float] | None) -> float:
        """(``ESTIMATE``) Before :meth:`setup`: the state estimate to start from (``None``:
        the controller's own start); returns the error bound it starts with."""
        raise CosimError(f"{self.where}: no state estimate")

    def estimate(self) -> tuple[Any, float, Any]:
        """(``ESTIMATE``) ``(x̂, its error bound, the steady state it steers to)`` now
        (normalised; ``None`` where there is none yet)."""
        raise CosimError(f"{self.where}: no state estimate")

    def prediction(self) -> Prediction | None:
        """(``PREDICTION``) The plan of the last step (``None`` before the first)."""
        return None

    def set(self, name: str, value: float) -> str:
        """(``SETTINGS``) Change setting ``name`` from the next step on; returns what was
        re-derived (one line, empty when nothing was). A value the component cannot take
        raises :class:`~cosim.core.errors.CosimError` naming it, the setting unchanged."""
        raise CosimError(f"{self.where}: no setting '{name}'")

    def operator_status(self) -> dict[str, Any]:
        """(``OPERATOR``) What it predicts now: ``prediction`` (by output, the outputs its
        plan predicts over the horizon, problem units) and ``prediction_error`` (by
        output, the RMS of its k-step errors so far); empty by default."""
        return {}
