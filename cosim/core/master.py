"""The co-simulation master: plant, sensor and controller in lockstep, driven by a scenario.

One communication step ``[t_k, t_k+1)`` (Gauss-Seidel, zero-order hold; see
:mod:`cosim.core.component` for the timing convention):

1. apply the scenario events due at ``t_k`` (set-points, measured disturbances, plant inputs
   and tunable parameters, sensor bias and noise);
2. read the plant outputs ``y(t_k)``;
3. the sensor (only when the scenario perturbs measurements) turns them into ``y_m(t_k)``;
4. the controller (direct feedthrough) computes ``u_k`` from ``y_m(t_k)`` and the set-points;
5. record the row ``t_k``;
6. the plant advances to ``t_k+1`` with ``u_k`` held.

Signals are wired by name: every controller input ``ref.<o>`` comes from the scenario, every
other controller input from the plant output of the same name, every controller output goes
to the plant input of the same name. A measured disturbance ``d`` (the problem's, or a
controller input ``dist.<d>``) is set on the plant input or tunable parameter ``d`` from the
scenario's ``dist.<d>`` column (else from the controller's ``disturbance_defaults``, its
nominal value) and handed to a controller that measures it as ``dist.<d>``. The master
knows nothing about the plant or the controller beyond that.

A fault in a step (FMU error or crash, controller exception, non-finite plant output) ends the
run: :meth:`Master.run` returns a :class:`RunResult` with status ``failed``, the reason, and
every row recorded before the fault; the caller writes it and re-raises ``result.error``.
"""

from __future__ import annotations

import contextlib
import math
import signal
from collections.abc import Callable

from cosim.core import interrupts
from cosim.core.component import Capability, Component
from cosim.core.errors import CosimError, ParameterError
from cosim.core.loop import Run
from cosim.core.operator import OperatorDesk
from cosim.core.pacing import ComponentIO, Pacer, PlantIO
from cosim.core.run_result import (
    MAX_STEPS,
    PREFIX_CTRL,
    PREFIX_DIST,
    PREFIX_PLANT,
    PREFIX_REF,
    PREFIX_SENSOR,
    RowSink,
    RunResult,
    RunWatcher,
    communication_times,
)
from cosim.core.scenario import BIAS, DIST, NOISE, PLANT, REF, UNIFORM, Scenario

__all__ = ["MAX_STEPS", "Master", "RowSink", "RunResult", "communication_times"]

class Master:
    """Steps ``plant`` and ``controller`` through ``scenario``.

    Parameters
    ----------
    plant : Component
        A component without direct feedthrough (an FMU); what it declares
        (:attr:`~cosim.core.component.Component.capabilities`: ``TUNABLE``, ``SIGNAL_CHECK``)
        is used as the loop is wired.
    controller : Component
        A direct-feedthrough component; inputs ``ref.<o>`` and measured plant outputs, outputs
        plant inputs; what it declares (``SETPOINTS``, ``DISTURBANCES``, ``PREVIEW``) is used
        as the loop is wired.
    scenario : Scenario
    step : float, optional
        Communication step [s]; default the controller's ``sample_time``. The controller is
        updated every ``sample_time / step`` steps (an integer) and held in between.
    seed : int
        Seed of the sensor noise.
    disturbances : sequence of str, optional
        The problem's measured disturbances (plant inputs or tunable parameters a
        ``dist.<name>`` column sets) besides those the controller measures; ``None`` (no
        problem known): every ``dist.<name>`` column of the scenario names one.
    io : PlantIO, optional
        How the loop reads, writes and advances the plant (:mod:`cosim.core.pacing`);
        default the component's own (:class:`~cosim.core.pacing.ComponentIO`).
    pacer : Pacer, optional
        When samples happen; default simulated time (:class:`~cosim.core.pacing.Pacer`).
    """

    def __init__(self, plant: Component, controller: Component, scenario: Scenario, *,
                 step: float | None = None, seed: int = 0,
                 disturbances: tuple[str, ...] | list[str] | None = None,
                 io: PlantIO | None = None, pacer: Pacer | None = None) -> None:
        self.plant = plant
        self.io: PlantIO = ComponentIO(plant) if io is None else io
        self.pacer = Pacer() if pacer is None else pacer
        self.controller = controller
        self.scenario = scenario
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ParameterError("seed", f" must be a non-negative integer, got {seed!r}")
        self.seed = seed
        if step is not None and not (math.isfinite(step) and step > 0):
            raise ParameterError("step", f" {step!r}: the communication step must be a "
                                 "positive, finite number of seconds")
        dt = step if step is not None else controller.sample_time
        if dt is None or not dt > 0:
            raise ParameterError("step", ": no communication step: the controller has no "
                                 "sample time; give one")
        self.dt = float(dt)
        self.given_disturbances = None if disturbances is None else tuple(disturbances)
        ts = controller.sample_time
        self.ratio = 1
        if ts is not None and step is not None:
            r = ts / self.dt
            if abs(r - round(r)) > 1e-9 or round(r) < 1:
                raise CosimError(f"communication step {self.dt!r} s does not divide the "
                                 f"controller's sample time {ts!r} s")
            self.ratio = round(r)
        n = (scenario.stop_time - scenario.start_time) / self.dt
        if n > MAX_STEPS:
            what = (f"{n:.3g} communication steps of {self.dt!r} s from "
                    f"{scenario.start_time!r} s to {scenario.stop_time!r} s, more than the "
                    f"{MAX_STEPS} allowed")
            if step is not None:
                raise ParameterError("step", f" {self.dt!r}: {what}")
            raise CosimError(f"{scenario.path}:{scenario.events[-1].line}:1: {what}")
        self._wire()

    # -- wiring -------------------------------------------------------------------------------
    def _wire(self) -> None:
        plant, ctrl, sc = self.plant, self.controller, self.scenario
        # a controller output drives an FMU input, or a tunable parameter (cosim.core.binding)
        plant_in = {s.name for s in plant.inputs} | set(plant.tunables)
        plant_out = [s.name for s in plant.outputs]
        self.ctrl_outputs = [s.name for s in ctrl.outputs]
        self.refs = [s.name[4:] for s in ctrl.inputs if s.name.startswith("ref.")]
        self.ctrl_dists = [s.name[5:] for s in ctrl.inputs if s.name.startswith("dist.")]
        given = self.given_disturbances
        if given is None:   # no problem known: the scenario's columns name them
            given = tuple(c.target for c in sc.columns_of(DIST))
        self.dists = list(dict.fromkeys([*given, *self.ctrl_dists]))
        self.measured = [s.name for s in ctrl.inputs
                         if not s.name.startswith(("ref.", "dist."))]
        where = plant.where
        units = {s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit}
        if Capability.SIGNAL_CHECK in plant.capabilities:
            plant.check_signals(self.ctrl_outputs, self.measured, units)
        self._check_bindings(plant_in, plant_out, where)
        at_start, later = plant.settable(True), plant.settable(False)
        #: the one checked entry of operator actions (:mod:`cosim.core.operator`): the
        #: set-points, the settings a controller declares and, for a controller an operator
        #: runs (``OPERATOR``), its ``op.*`` settings, which a scenario may act on
        self.desk = OperatorDesk(ctrl)
        check = (None if Capability.OPERATOR not in ctrl.capabilities else
                 lambda name, value: self.desk.check(name, value, "engineer")[0])
        sc.validate(at_start, self.refs, self.measured, driven=[*self.ctrl_outputs, *self.dists],
                    plant_tunable=later, disturbances=self.dists, operator=check)
        given = {c.target for c in sc.columns_of(REF)}
        for r in self.refs:
            if r not in given:
                raise CosimError(f"{sc.path}:1:1: no column 'ref.{r}': the controller needs a "
                                 f"set-point for '{r}'")
        given_d = {c.target for c in sc.columns_of(DIST)}
        defaults = (dict(ctrl.disturbance_defaults)
                    if Capability.DISTURBANCES in ctrl.capabilities else {})
        self.dist_defaults = {}
        for d in self.dists:
            if d in given_d:
                continue
            if d not in defaults:
                raise CosimError(f"{sc.path}:1:1: no column 'dist.{d}': the controller "
                                 f"measures the disturbance '{d}'; give its value")
            self.dist_defaults[d] = float(defaults[d])
        self.plant_outputs = plant_out
        self.refs_keys = [f"ref.{r}" for r in self.refs]
        self.scenario_plant = [c.target for c in sc.columns_of(PLANT)]
        self.use_sensor = bool(sc.columns_of(BIAS) or sc.columns_of(NOISE)
                               or sc.columns_of(UNIFORM))

    def _check_bindings(self, plant_in: set[str], plant_out: list[str], where: str) -> None:
        """Every controller output and measured disturbance drives a plant input or tunable
        parameter, every measured controller input is a plant output."""
        for u in self.ctrl_outputs:
            if u not in plant_in:
                raise CosimError(f"{where}: controller output '{u}' is not an input of the plant"
                                 " (use --map to map it onto the plant's variable)")
        for y in self.measured:
            if y not in plant_out:
                raise CosimError(f"{where}: controller input '{y}' is not an output of the plant"
                                 " (use --map to map it onto the plant's variable)")
        for d in self.dists:
            if d not in plant_in:
                raise CosimError(f"{where}: measured disturbance '{d}' is not an input or "
                                 "tunable parameter of the plant (give the problem that binds "
                                 "it, --problem, name its variable with variable = \"...\" "
                                 "there, or use --map)")

    def columns(self) -> list[str]:
        """Recorded columns, diagnostics excluded (they are appended as they appear).

        ``time``, ``ref.<o>`` (set-points), ``dist.<d>`` (measured disturbances, as set on
        the plant), ``plant.<v>`` (plant inputs/parameters the scenario
        sets, then every plant output), ``sensor.<o>`` (measured values seen by the controller,
        only when the scenario perturbs them), ``ctrl.<u>`` (controller outputs, i.e. the plant
        inputs it drives), then ``ctrl.<d>`` per controller diagnostic.

        ``plant.<u>`` (before ``ctrl.<u>``): the input the plant actually got each sample
        (the controller's in auto, the operator's in manual, the held value of an input out
        of service: :mod:`cosim.core.operator`); ``ctrl.<u>`` what the controller computed.
        """
        cols = ["time"]
        cols += [f"{PREFIX_REF}.{r}" for r in self.refs]
        cols += [f"{PREFIX_DIST}.{d}" for d in self.dists]
        cols += [f"{PREFIX_PLANT}.{p}" for p in self.scenario_plant]
        cols += [f"{PREFIX_PLANT}.{y}" for y in self.plant_outputs]
        if self.use_sensor:
            cols += [f"{PREFIX_SENSOR}.{m}" for m in self.measured]
        cols += [f"{PREFIX_PLANT}.{u}" for u in self.ctrl_outputs]
        cols += [f"{PREFIX_CTRL}.{u}" for u in self.ctrl_outputs]
        return cols

    # -- run ----------------------------------------------------------------------------------
    def run(self, on_step: Callable[[int], None] | None = None, *,
            record: RowSink | None = None, step_timeout: float | None = None,
            deadline: float | None = None, watch: RunWatcher | None = None) -> RunResult:
        """Run the scenario; never raises for a fault inside the run (see ``result.error``).

        Parameters
        ----------
        on_step : callable, optional
            Called with the number of completed plant steps after each step (progress bars).
        record : RowSink, optional
            Receives every row as it is recorded (``record.append(row, columns)``), e.g. a
            :class:`cosim.core.results.ResultsStream` that streams ``results.csv`` to disk. An
            exception it raises ends the run (status ``failed``).
        step_timeout : float, optional
            Wall-clock limit [s] of one controller step: a controller that runs in a worker
            process (``isolated``: a controller FMU, :mod:`cosim.core.isolated`) gets it as
            its own ``timeout`` and kills its worker past it; any other is stopped by
            ``SIGALRM`` in the main thread (a controller hung in Python code; elsewhere the
            step is measured after it returns). Plant steps are bounded by the plant itself
            (see :class:`cosim.core.isolated.IsolatedFmuComponent`).
        deadline : float, optional
            ``time.monotonic()`` value past which the run stops with status ``failed``
            (checked between steps: the whole-run timeout of campaigns).
        watch : RunWatcher, optional
            Follows the run from its loop (:class:`~cosim.core.run_result.RunWatcher`: a
            live page, :mod:`cosim.hmi`): each row, and set-points changed between steps.

        Raises
        ------
        CosimError
            Only for problems found before the first step.
        """
        if step_timeout is not None and not (math.isfinite(step_timeout) and step_timeout > 0):
            raise ParameterError("step_timeout", f" {step_timeout!r}: expected a positive "
                                 "number of seconds")
        run = Run(self, record, step_timeout, deadline, watch)
        own = interrupts.current() is None
        with interrupts.handling_signals() as guard:
            run.guard = guard
            # signals raise inside the step loop only; elsewhere they are recorded
            with guard.deferred() if guard is not None else contextlib.nullcontext():
                run.execute(on_step)
        if own and guard is not None and guard.signum is not None \
                and run.result.status != "interrupted":
            # arrived while the run was being wound up: deliver it to the caller's handler
            signal.raise_signal(guard.signum)
        return run.result
