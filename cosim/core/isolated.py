"""Components whose native code runs in a worker process: :class:`IsolatedFmuComponent` (a
plant FMU, ``cosim run --isolate``), :class:`IsolatedFmuController` (a controller FMU: always)
and :class:`IsolatedController` (a Python controller, ``cosim run --isolate``).

Each keeps what a run asks of it in this process (an FMU's modelDescription and variable
map; a Python controller built here too, for its signals and checks) and runs the native
code in a :class:`~cosim.core.worker.Worker`, which a crash cannot take down and a timeout
can kill: one round trip per step (inputs in, outputs out).

* When the worker dies (segfault, ``abort()``, ``exit()``, killed), the step raises
  :class:`~cosim.core.errors.SimulationFailed` ``"... worker died (signal 11, SIGSEGV)"`` and the
  master keeps every row recorded so far.
* With a ``timeout``, a request the worker has not answered within that many seconds kills
  the worker (SIGKILL) and fails the step: ``"doStep at t=500.0 took longer than the step
  timeout of 5 s (worker killed)"``. The master hands an isolated controller the run's step
  timeout (:attr:`isolated`), since a ``SIGALRM`` cannot stop native code.
* A signal that interrupts the parent while the worker is busy (Ctrl-C, SIGTERM) kills the
  worker at once in :meth:`IsolatedFmuComponent.terminate`: nothing waits for a hung FMU.
* An FMU is extracted into the worker's scratch folder, which this process creates and
  removes, so nothing is left behind however the worker ends.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cosim.core.component import Component, Schedule
from cosim.core.errors import CosimError, ParameterError, SimulationFailed
from cosim.core.fmu import FmuComponent
from cosim.core.fmu_controller import FmuController
from cosim.core.varmap import MappedSignal, VarMap
from cosim.core.worker import Worker

__all__ = ["DEFAULT_STEP_TIMEOUT", "REHEARSAL_TIMEOUT", "ComponentServer", "IsolatedController",
           "IsolatedFmuComponent", "IsolatedFmuController", "Isolation", "rehearse"]

#: Step timeout [s] of an isolated FMU when none is given (``cosim run --isolate``, a
#: controller FMU): far above any healthy step of a process model or a controller, short
#: enough that a hung FMU is noticed.
DEFAULT_STEP_TIMEOUT = 60.0
#: Wall-clock limit [s] of each request of :func:`rehearse` (a healthy FMU answers in far
#: less).
REHEARSAL_TIMEOUT = 30.0


def _call(worker: Worker | None, label: str, what: str, method: str, *args: Any) -> Any:
    """``worker.call(what, method, *args)``; a component that has no worker (never set up, or
    terminated) fails the call in the same words."""
    if worker is None:
        raise SimulationFailed(f"{label}: {what} failed: no worker")
    return worker.call(what, method, *args)


def fmu_component(path: str, name: str, interface: str,
                  start_values: tuple[tuple[str, float], ...],
                  mapping: tuple[tuple[str, str, str | None, float, float], ...],
                  map_path: str, scratch: str) -> FmuComponent:  # pragma: no cover - worker
    """The :class:`~cosim.core.fmu.FmuComponent` a worker runs (its variable map rebuilt
    from plain data), extracted into the worker's ``scratch`` folder."""
    varmap = VarMap(Path(map_path), {m[0]: MappedSignal(*m) for m in mapping})
    return FmuComponent(path, name=name, interface=interface, start_values=dict(start_values),
                        varmap=varmap, unpack_dir=scratch)


class ComponentServer:  # pragma: no cover - runs in the worker process
    """Any component served by a worker (the one server of this module): built from a
    ``module:function`` and its keyword arguments (``scratch``: the worker's folder, when
    asked for); each request answers with the outputs, in the order of its ``outputs``."""

    def __init__(self, factory: str, kwargs: dict[str, Any], scratch: str | None = None
                 ) -> None:
        module, _, name = factory.partition(":")
        import importlib

        build = getattr(importlib.import_module(module), name)
        self.comp = build(**kwargs, **({"scratch": scratch} if scratch else {}))

    def setup(self, t0: float) -> tuple[float, ...] | None:
        """Set up at ``t0``; a plant's outputs then (a controller has none before its first
        step)."""
        self.comp.setup(t0)
        if self.comp.direct_feedthrough:
            return None
        return tuple(self.comp.get_outputs().values())

    def step(self, t: float, dt: float, inputs: tuple[tuple[str, float], ...]
             ) -> tuple[float, ...]:
        """A plant's step: inputs, ``step``, the outputs' values."""
        if inputs:
            self.comp.set_inputs(dict(inputs))
        self.comp.step(t, dt)
        return tuple(self.comp.get_outputs().values())

    def control(self, t: float, dt: float, inputs: tuple[tuple[str, float], ...]
                ) -> tuple[tuple[tuple[str, float], ...], tuple[tuple[str, Any], ...]]:
        """A controller's step: inputs, ``step``, its outputs and diagnostics."""
        self.comp.set_inputs(dict(inputs))
        self.comp.step(t, dt)
        return tuple(self.comp.get_outputs().items()), tuple(self.comp.diagnostics().items())

    def set_parameter(self, name: str, value: float) -> tuple[float, ...]:
        self.comp.set_parameter(name, value)
        return tuple(self.comp.get_outputs().values())

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        self.comp.expect_setpoints(setpoints)

    def set_schedule(self, schedules: Mapping[str, Schedule] | None) -> None:
        self.comp.set_schedule(schedules)

    def set(self, name: str, value: float) -> str:
        return self.comp.set(name, value)

    def operator_status(self) -> dict:
        return dict(self.comp.operator_status() or {})

    def prediction(self) -> Any:
        return self.comp.prediction()

    def summary(self) -> dict:
        return dict(self.comp.summary() or {})

    def close(self) -> None:
        self.comp.terminate()


class Isolation:
    """The isolation proxy: a component whose steps run in a worker process (module
    docstring), and every capability it declares (:class:`~cosim.core.component.
    Capability`) forwarded there: parameters (``TUNABLE``), the run's set-points
    (``SETPOINTS``), schedules as data (``PREVIEW``), settings (``SETTINGS``) and the plan
    (``PREDICTION``). What it
    declares it answers from this process (names, boxes, defaults, its notice).

    A class mixes it in before the component it isolates and says how the worker builds
    that component (:meth:`_factory`); :attr:`timeout` bounds every request (``None``:
    none)."""

    isolated = True
    #: whether the worker's component is a controller (outputs and diagnostics per step)
    _controller = False

    def _isolation_init(self, timeout: float | None) -> None:
        self._worker: Worker | None = None
        self._pending: dict[str, float] = {}
        self._outputs: dict[str, float] = {}
        self._diag: dict[str, Any] = {}
        self._setpoints: list[dict[str, float]] | None = None
        self.timeout = timeout

    @property
    def timeout(self) -> float | None:
        """Wall-clock limit [s] of every request to the worker (``None``: none)."""
        return self._timeout

    @timeout.setter
    def timeout(self, value: float | None) -> None:
        if value is not None and not (value > 0 and value < float("inf")):
            raise ParameterError("step_timeout", f" {value!r}: expected a positive number "
                                 "of seconds")
        self._timeout = value
        worker = getattr(self, "_worker", None)
        if worker is not None:
            worker.timeout = value

    @property
    def label(self) -> str:
        """How messages name this component."""
        return f"controller {self.name!r}"

    def _factory(self) -> tuple[str, dict[str, Any], bool]:
        """``(module:function, keyword arguments, scratch)``: how the worker builds the
        component (``scratch``: it gets a folder of its own)."""
        raise NotImplementedError

    def _call(self, what: str, method: str, *args: Any) -> Any:
        return _call(self._worker, self.label, what, method, *args)

    def _start_worker(self, t0: float, build_timeout: float | None) -> None:
        """A new worker building the component, told the set-points, set up at ``t0``."""
        self.terminate()
        factory, kwargs, scratch = self._factory()
        self._worker = Worker(self.label, "cosim.core.isolated:ComponentServer",
                              {"factory": factory, "kwargs": kwargs}, timeout=build_timeout,
                              scratch=scratch)
        self._worker.start()
        if self._setpoints is not None:
            self._worker.call("expecting the set-points", "expect_setpoints", self._setpoints)
        self._pending.clear()
        values = self._worker.call(f"initialisation at t={t0!r}", "setup", float(t0))
        self._worker.timeout = self.timeout
        if values is not None:
            self._outputs = dict(zip(self._out_names, values, strict=True))

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Inputs travel with the next step request."""
        self._pending.update(values)

    def step(self, t: float, dt: float) -> None:
        """One round trip: the inputs, the component's step, its outputs (a controller's
        diagnostics too)."""
        inputs = tuple((k, float(v)) for k, v in self._pending.items())
        self._pending.clear()
        if self._controller:
            outputs, diag = self._call(f"step at t={t!r}", "control", float(t), float(dt),
                                       inputs)
            self._outputs, self._diag = dict(outputs), dict(diag)
            return
        vals = self._call(f"doStep at t={t!r}", "step", float(t), float(dt), inputs)
        self._outputs = dict(zip(self._out_names, vals, strict=True))
        self._t = t + dt

    def get_outputs(self) -> dict[str, float]:
        """Outputs returned by the last request."""
        return dict(self._outputs)

    def diagnostics(self) -> dict[str, Any]:
        """Diagnostics of the last step (a controller's)."""
        return dict(self._diag)

    # -- the declared capabilities, forwarded --------------------------------------------------
    def set_parameter(self, name: str, value: float) -> None:
        """(``TUNABLE``) In the worker (before it starts: a start value)."""
        if self._worker is None or not self._worker.alive:
            self.start_values[name] = value
            return
        vals = self._call(f"setting {name}", "set_parameter", name, float(value))
        self._outputs = dict(zip(self._out_names, vals, strict=True))

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """(``SETPOINTS``) Checked here (a refusal is bad input); handed to the worker when
        it starts."""
        super().expect_setpoints(setpoints)  # type: ignore[misc]
        self._setpoints = [dict(s) for s in setpoints]

    def set_schedule(self, schedules: Mapping[str, Schedule] | None) -> None:
        """(``PREVIEW``) The schedules, as data, to the worker's component."""
        self._call("handing over the schedules", "set_schedule",
                   None if schedules is None else dict(schedules))

    def set(self, name: str, value: float) -> str:
        """(``SETTINGS``) In the worker's component; what it re-derived."""
        return self._call(f"setting {name}", "set", name, float(value))

    def operator_status(self) -> dict[str, Any]:
        """(``OPERATOR``) The worker's component's predictions."""
        return self._call("reading the operator status", "operator_status")

    def prediction(self) -> Any:
        """(``PREDICTION``) The worker's component's plan of its last step."""
        return self._call("reading the plan", "prediction")

    def summary(self) -> dict:
        """The worker's component's summary (:meth:`_summary_here` when the worker is
        gone)."""
        worker = self._worker
        if worker is not None and worker.alive and not worker.busy:
            try:
                return worker.call("summarising the run", "summary")
            except CosimError:
                pass
        return dict(self._summary_here() or {})

    def _summary_here(self) -> dict | None:
        """The summary this process knows (the component's own class's)."""
        return super().summary()  # type: ignore[misc]

    def terminate(self) -> None:
        """Stop the worker and remove its folder (idempotent).

        A worker still busy with a request (the parent was interrupted while waiting) is
        killed at once; an idle one is asked to end the component and given
        :data:`cosim.core.worker.TERMINATE_WAIT` seconds.
        """
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop()


class IsolatedFmuComponent(Isolation, FmuComponent):
    """Same interface as :class:`FmuComponent`; the FMU runs in a worker process, extracted
    into the worker's folder.

    Parameters
    ----------
    *args, **kwargs
        As :class:`FmuComponent`.
    timeout : float, optional
        Wall-clock limit [s] of every request to the worker (initialisation, each
        ``doStep``, parameter changes); past it the worker is killed and the request fails.
        ``None``: wait for ever.
    """

    def __init__(self, *args: Any, timeout: float | None = None, **kwargs: Any) -> None:
        FmuComponent.__init__(self, *args, **kwargs)
        self._isolation_init(timeout)

    @property
    def label(self) -> str:
        """How messages name this FMU."""
        return self.path.name

    def _factory(self) -> tuple[str, dict[str, Any], bool]:
        mapping = tuple((m.signal, m.variable, m.unit, m.scale, m.offset)
                        for m in self.varmap.signals.values())
        return "cosim.core.isolated:fmu_component", {
            "path": str(self.path), "name": self.name, "interface": self.interface,
            "start_values": tuple((k, float(v)) for k, v in self.start_values.items()),
            "mapping": mapping, "map_path": str(self.varmap.path)}, True

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Start the worker, which extracts, loads and initialises the FMU."""
        self._t = t0
        self._start_worker(t0, self.timeout)


class IsolatedFmuController(FmuController, IsolatedFmuComponent):
    """A controller FMU (:class:`~cosim.core.fmu_controller.FmuController`) whose native code
    runs in a worker process: what ``cosim run --controller Controller.fmu`` and campaigns
    step. Its requests time out after :data:`DEFAULT_STEP_TIMEOUT` seconds unless the run
    gives a step timeout (``--step-timeout``: the master sets :attr:`timeout`)."""

    def __init__(self, path: str | Path, name: str = "ctrl", **parameters: Any) -> None:
        FmuController.__init__(self, path, name, **parameters)
        self.timeout = DEFAULT_STEP_TIMEOUT

    @property
    def label(self) -> str:
        """Messages name the controller FMU as such."""
        return f"controller FMU {self.path.name}"


class IsolatedController(Isolation, Component):
    """A controller of the registry whose steps run in a worker process (``cosim run
    --isolate``): a Python controller stuck in native code (a solver, a compiled kernel) or
    crashing in it ends the run as an isolated FMU does.

    The controller is built here too (``local``: its signals, sample time, bounds,
    declarations and every check of its options, before anything runs), and again in the
    worker from its registry name and options, which runs it.

    Parameters
    ----------
    local : Component
        The controller built in this process (:func:`cosim.core.registry.create`).
    controller : str
        Its registry name (or ``module:Class``, or controller file).
    options : mapping
        Its options (picklable: they travel to the worker).
    """

    _controller = True

    def __init__(self, local: Component, controller: str, options: Mapping[str, Any]) -> None:
        self.local = local
        self.controller = controller
        self.options = dict(options)
        self.name = local.name
        self.inputs, self.outputs = local.inputs, local.outputs
        self.direct_feedthrough = local.direct_feedthrough
        self.sample_time = local.sample_time
        self.bounds = dict(local.bounds)
        self.timing_diagnostics = local.timing_diagnostics
        # what it declares, answered here; what it does, in the worker
        self.capabilities = local.capabilities
        self.disturbance_defaults = dict(local.disturbance_defaults)
        self.previewed = tuple(local.previewed)
        self.problem = local.problem
        self._isolation_init(DEFAULT_STEP_TIMEOUT)

    @property
    def notice(self) -> str | None:  # type: ignore[override]
        """(``NOTICE``) The local controller's (its design decides it)."""
        return self.local.notice

    def plant_signals(self) -> Any:
        return self.local.plant_signals()

    def settings(self) -> Any:
        return self.local.settings()

    def _factory(self) -> tuple[str, dict[str, Any], bool]:
        return "cosim.core.registry:create", {"name": self.controller,
                                              "options": self.options}, False

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """Checked here (a refusal is bad input); handed to the worker at :meth:`setup`."""
        self.local.expect_setpoints(setpoints)
        self._setpoints = [dict(s) for s in setpoints]

    def setup(self, t0: float) -> None:
        """Start the worker, which builds the controller, and set it up at ``t0``
        (building it, its certificate and solver, takes longer than a step)."""
        build = None if self.timeout is None else max(self.timeout, DEFAULT_STEP_TIMEOUT)
        self._start_worker(t0, build)

    def _summary_here(self) -> dict | None:
        """The local controller's summary (:meth:`Isolation.summary` when the worker is
        gone)."""
        return self.local.summary()

    def terminate(self) -> None:
        """Stop the worker (idempotent; a busy one is killed at once)."""
        Isolation.terminate(self)
        self.local.terminate()


def rehearse(fmus: Sequence[tuple[IsolatedFmuComponent, Mapping[str, float]]],
             step_size: float) -> None:
    """Set up each FMU at ``t = 0``, set its inputs (each pair's mapping) and step it once by
    ``step_size``, each in its worker (a crash or a hang fails the rehearsal, not this
    process; every request bounded by :data:`REHEARSAL_TIMEOUT`); then end them.

    Raises
    ------
    SimulationFailed
        An FMU failed, crashed or hung: how, in one line.
    CosimError
        An FMU refused a start value (bad input).
    """
    try:
        for fmu, _ in fmus:
            fmu.timeout = REHEARSAL_TIMEOUT
            fmu.setup(0.0)
        for fmu, inputs in fmus:
            fmu.set_inputs(inputs)
            fmu.step(0.0, step_size)
    finally:
        for fmu, _ in fmus:
            fmu.terminate()
