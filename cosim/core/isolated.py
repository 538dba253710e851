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

from cosim.core.component import Component
from cosim.core.errors import CosimError, ParameterError, SimulationFailed
from cosim.core.fmu import FmuComponent
from cosim.core.fmu_controller import FmuController
from cosim.core.varmap import MappedSignal, VarMap
from cosim.core.worker import Worker

__all__ = ["DEFAULT_STEP_TIMEOUT", "REHEARSAL_TIMEOUT", "ControllerServer", "FmuServer",
           "IsolatedController", "IsolatedFmuComponent", "IsolatedFmuController", "rehearse"]

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


class FmuServer:  # pragma: no cover - runs in the worker process
    """An :class:`~cosim.core.fmu.FmuComponent` served by a worker: each request answers with
    the outputs, in the modelDescription's order."""

    def __init__(self, path: str, name: str, interface: str,
                 start_values: tuple[tuple[str, float], ...],
                 mapping: tuple[tuple[str, str, str | None, float, float], ...],
                 map_path: str, scratch: str) -> None:
        varmap = VarMap(Path(map_path), {m[0]: MappedSignal(*m) for m in mapping})
        self.comp = FmuComponent(path, name=name, interface=interface,
                                 start_values=dict(start_values), varmap=varmap,
                                 unpack_dir=scratch)

    def setup(self, t0: float) -> tuple[tuple[str, float], ...]:
        self.comp.setup(t0)
        return tuple(self.comp.get_outputs().items())

    def step(self, t: float, dt: float, inputs: tuple[tuple[str, float], ...]
             ) -> tuple[float, ...]:
        if inputs:
            self.comp.set_inputs(dict(inputs))
        self.comp.step(t, dt)
        return tuple(self.comp.get_outputs().values())

    def set_parameter(self, name: str, value: float) -> tuple[float, ...]:
        self.comp.set_parameter(name, value)
        return tuple(self.comp.get_outputs().values())

    def close(self) -> None:
        self.comp.terminate()


class IsolatedFmuComponent(FmuComponent):
    """Same interface as :class:`FmuComponent`; the FMU runs in a worker process.

    Parameters
    ----------
    *args, **kwargs
        As :class:`FmuComponent`.
    timeout : float, optional
        Wall-clock limit [s] of every request to the worker (initialisation, each
        ``doStep``, parameter changes); past it the worker is killed and the request fails.
        ``None``: wait for ever.
    """

    #: The FMU's native code runs in a worker process, whose requests :attr:`timeout` bounds.
    isolated = True

    def __init__(self, *args: Any, timeout: float | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.timeout = timeout
        self._worker: Worker | None = None
        self._pending: dict[str, float] = {}
        self._outputs: dict[str, float] = {}

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
        """How messages name this FMU."""
        return self.path.name

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Start the worker, which extracts, loads and initialises the FMU."""
        self.terminate()
        mapping = tuple((m.signal, m.variable, m.unit, m.scale, m.offset)
                        for m in self.varmap.signals.values())
        self._worker = Worker(
            self.label, "cosim.core.isolated:FmuServer",
            {"path": str(self.path), "name": self.name, "interface": self.interface,
             "start_values": tuple((k, float(v)) for k, v in self.start_values.items()),
             "mapping": mapping, "map_path": str(self.varmap.path)},
            timeout=self.timeout, scratch=True)
        self._worker.start()
        self._pending.clear()
        self._t = t0
        self._outputs = dict(self._call(f"initialisation at t={t0!r}", "setup", float(t0)))

    def _call(self, what: str, method: str, *args: Any) -> Any:
        return _call(self._worker, self.label, what, method, *args)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Inputs travel with the next step request."""
        self._pending.update(values)

    def set_parameter(self, name: str, value: float) -> None:
        """Change a tunable parameter in the worker (or a start value before setup)."""
        if self._worker is None or not self._worker.alive:
            self.start_values[name] = value
            return
        vals = self._call(f"setting {name}", "set_parameter", name, float(value))
        self._outputs = dict(zip(self._out_names, vals, strict=True))

    def step(self, t: float, dt: float) -> None:
        """One round trip: inputs, ``doStep``, outputs."""
        inputs = tuple((k, float(v)) for k, v in self._pending.items())
        self._pending.clear()
        vals = self._call(f"doStep at t={t!r}", "step", float(t), float(dt), inputs)
        self._outputs = dict(zip(self._out_names, vals, strict=True))
        self._t = t + dt

    def get_outputs(self) -> dict[str, float]:
        """Outputs returned by the last request."""
        return dict(self._outputs)

    def terminate(self) -> None:
        """Stop the worker and remove its folder (idempotent).

        A worker still busy with a request (the parent was interrupted while waiting) is
        killed at once; an idle one is asked to terminate the FMU and given
        :data:`cosim.core.worker.TERMINATE_WAIT` seconds.
        """
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop()


class IsolatedFmuController(FmuController, IsolatedFmuComponent):
    """A controller FMU (:class:`~cosim.core.fmu_controller.FmuController`) whose native code
    runs in a worker process: what ``cosim run --controller Controller.fmu`` and campaigns
    step. Its requests time out after :data:`DEFAULT_STEP_TIMEOUT` seconds unless the run
    gives a step timeout (``--step-timeout``: the master sets :attr:`timeout`)."""

    def __init__(self, path: str | Path, name: str = "ctrl", **parameters: Any) -> None:
        super().__init__(path, name, **parameters)
        self.timeout = DEFAULT_STEP_TIMEOUT

    @property
    def label(self) -> str:
        """Messages name the controller FMU as such."""
        return f"controller FMU {self.path.name}"


class ControllerServer:  # pragma: no cover - runs in the worker process
    """A controller of the registry (:func:`cosim.core.registry.create`) served by a worker:
    each step answers with its outputs and diagnostics."""

    def __init__(self, controller: str, options: dict[str, Any]) -> None:
        from cosim.core import registry

        self.ctrl = registry.create(controller, options)

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        self.ctrl.expect_setpoints(setpoints)

    def setup(self, t0: float) -> None:
        self.ctrl.setup(t0)

    def step(self, t: float, dt: float, inputs: tuple[tuple[str, float], ...]
             ) -> tuple[tuple[tuple[str, float], ...], tuple[tuple[str, Any], ...]]:
        self.ctrl.set_inputs(dict(inputs))
        self.ctrl.step(t, dt)
        return tuple(self.ctrl.get_outputs().items()), tuple(self.ctrl.diagnostics().items())

    def summary(self) -> dict:
        return dict(self.ctrl.summary() or {})

    def close(self) -> None:
        self.ctrl.terminate()


class IsolatedController(Component):
    """A controller of the registry whose steps run in a worker process (``cosim run
    --isolate``): a Python controller stuck in native code (a solver, a compiled kernel) or
    crashing in it ends the run as an isolated FMU does.

    The controller is built here too (``local``: its signals, sample time, bounds, notice and
    problem, and every check of its options, before anything runs), and again in the worker
    from its registry name and options, which runs it.

    Parameters
    ----------
    local : Component
        The controller built in this process (:func:`cosim.core.registry.create`).
    controller : str
        Its registry name (or ``module:Class``, or controller file).
    options : mapping
        Its options (picklable: they travel to the worker).
    """

    isolated = True

    def __init__(self, local: Component, controller: str, options: Mapping[str, Any]) -> None:
        self.local = local
        self.controller = controller
        self.options = dict(options)
        self.name = local.name
        self.inputs, self.outputs = local.inputs, local.outputs
        self.direct_feedthrough = local.direct_feedthrough
        self.sample_time = local.sample_time
        self.bounds = dict(getattr(local, "bounds", {}) or {})
        self.timing_diagnostics = local.timing_diagnostics
        self.timeout: float | None = DEFAULT_STEP_TIMEOUT
        self._worker: Worker | None = None
        self._setpoints: list[dict[str, float]] | None = None
        self._pending: dict[str, float] = {}
        self._outputs: dict[str, float] = {}
        self._diag: dict[str, Any] = {}

    def __getattr__(self, name: str) -> Any:
        """What else a run asks the controller (its ``notice``, its ``problem``): the local
        one's."""
        if name.startswith("_") or name == "local":
            raise AttributeError(name)
        return getattr(self.local, name)

    @property
    def label(self) -> str:
        """How messages name this controller."""
        return f"controller {self.name!r}"

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """Checked here (a refusal is bad input); handed to the worker at :meth:`setup`."""
        self.local.expect_setpoints(setpoints)
        self._setpoints = [dict(s) for s in setpoints]

    def setup(self, t0: float) -> None:
        """Start the worker, which builds the controller, and set it up at ``t0``."""
        self.terminate()
        # building a controller (its certificate, its solver) takes longer than a step
        build = None if self.timeout is None else max(self.timeout, DEFAULT_STEP_TIMEOUT)
        self._worker = Worker(self.label, "cosim.core.isolated:ControllerServer",
                              {"controller": self.controller, "options": self.options},
                              timeout=build)
        self._worker.start()
        if self._setpoints is not None:
            self._worker.call("expecting the set-points", "expect_setpoints", self._setpoints)
        self._worker.call(f"setup at t={t0!r}", "setup", float(t0))
        self._pending.clear()

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Inputs travel with the next step request."""
        self._pending.update(values)

    def step(self, t: float, dt: float) -> None:
        """One round trip: inputs, the controller's step, outputs and diagnostics."""
        inputs = tuple((k, float(v)) for k, v in self._pending.items())
        self._pending.clear()
        if self._worker is not None:
            self._worker.timeout = self.timeout
        outputs, diag = _call(self._worker, self.label, f"step at t={t!r}", "step", float(t),
                              float(dt), inputs)
        self._outputs, self._diag = dict(outputs), dict(diag)

    def get_outputs(self) -> dict[str, float]:
        """Outputs of the last step."""
        return dict(self._outputs)

    def diagnostics(self) -> dict[str, Any]:
        """Diagnostics of the last step."""
        return dict(self._diag)

    def summary(self) -> dict:
        """The worker's controller's summary (the local one's when the worker is gone)."""
        worker = self._worker
        if worker is not None and worker.alive and not worker.busy:
            try:
                return worker.call("summarising the run", "summary")
            except CosimError:
                pass
        return dict(self.local.summary() or {})

    def terminate(self) -> None:
        """Stop the worker (idempotent; a busy one is killed at once)."""
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop()
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
