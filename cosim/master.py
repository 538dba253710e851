"""The co-simulation master: plant, sensor and controller in lockstep, driven by a scenario.

One communication step ``[t_k, t_k+1)`` (Gauss-Seidel, zero-order hold; see
:mod:`cosim.component` for the timing convention):

1. apply the scenario events due at ``t_k`` (set-points, plant inputs and tunable parameters,
   sensor bias and noise);
2. read the plant outputs ``y(t_k)``;
3. the sensor (only when the scenario perturbs measurements) turns them into ``y_m(t_k)``;
4. the controller (direct feedthrough) computes ``u_k`` from ``y_m(t_k)`` and the set-points;
5. record the row ``t_k``;
6. the plant advances to ``t_k+1`` with ``u_k`` held.

Signals are wired by name: every controller input ``ref.<o>`` comes from the scenario, every
other controller input from the plant output of the same name, every controller output goes
to the plant input of the same name. The master knows nothing about the plant or the
controller beyond that.

A fault in a step (FMU error or crash, controller exception, non-finite plant output) ends the
run: :meth:`Master.run` returns a :class:`RunResult` with status ``failed``, the reason, and
every row recorded before the fault; the caller writes it and re-raises ``result.error``.
"""

from __future__ import annotations

import contextlib
import math
import signal
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from cosim import interrupts
from cosim.component import Component
from cosim.errors import CosimError, SimulationFailed
from cosim.scenario import BIAS, NOISE, PLANT, REF, Scenario
from cosim.sensor import SensorModel

#: Column prefixes of recorded signals (results.csv).
PREFIX_REF, PREFIX_PLANT, PREFIX_SENSOR, PREFIX_CTRL = "ref", "plant", "sensor", "ctrl"


@dataclass
class RunResult:
    """Everything a run recorded, complete or up to a fault.

    Attributes
    ----------
    columns : list of str
        ``time`` then one name per recorded signal (see :func:`Master.columns`).
    rows : list of list of float
        One row per communication point reached.
    status : str
        ``"ok"``, ``"failed"`` or ``"interrupted"``.
    reason : str
        Why the run failed (empty when ok).
    steps : int
        Plant steps completed.
    steps_planned : int
        Plant steps the scenario asks for.
    """

    columns: list[str]
    rows: list[list[float]]
    status: str = "ok"
    reason: str = ""
    steps: int = 0
    steps_planned: int = 0
    step_size: float = 0.0
    start_time: float = 0.0
    stop_time: float = 0.0
    outputs: list[str] = field(default_factory=list)
    references: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    perturbation_times: list[float] = field(default_factory=list)
    controller_summary: dict = field(default_factory=dict)
    timing_columns: list[str] = field(default_factory=list)
    timing_rows: list[list[float]] = field(default_factory=list)
    wall_time_s: float = 0.0
    loop_time_s: float = 0.0
    error: BaseException | None = None


#: Most communication steps one run may take (results are held in memory).
MAX_STEPS = 1_000_000


def communication_times(t0: float, stop: float, dt: float) -> list[float]:
    """``t0, t0 + dt, ...`` up to ``stop``; a last, shorter step lands exactly on ``stop``."""
    n = math.floor((stop - t0) / dt + 1e-9)
    times = [t0 + k * dt for k in range(n + 1)]
    if stop - times[-1] > 1e-9 * dt:
        times.append(stop)
    else:
        times[-1] = stop
    return times


class Master:
    """Steps ``plant`` and ``controller`` through ``scenario``.

    Parameters
    ----------
    plant : Component
        A component without direct feedthrough (an FMU); optional methods ``settable(at_start)``
        (names a scenario may set), ``set_parameter(name, value)`` and ``check_signals``.
    controller : Component
        A direct-feedthrough component; inputs ``ref.<o>`` and measured plant outputs, outputs
        plant inputs.
    scenario : Scenario
    step : float, optional
        Communication step [s]; default the controller's ``sample_time``. The controller is
        updated every ``sample_time / step`` steps (an integer) and held in between.
    seed : int
        Seed of the sensor noise.
    """

    def __init__(self, plant: Component, controller: Component, scenario: Scenario, *,
                 step: float | None = None, seed: int = 0) -> None:
        self.plant = plant
        self.controller = controller
        self.scenario = scenario
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise CosimError(f"--seed must be a non-negative integer, got {seed!r}")
        self.seed = seed
        if step is not None and not (math.isfinite(step) and step > 0):
            raise CosimError(f"--step {step!r}: the communication step must be a positive, "
                             "finite number of seconds")
        dt = step if step is not None else controller.sample_time
        if dt is None or not dt > 0:
            raise CosimError("no communication step: the controller has no sample time; "
                             "give one with --step")
        self.dt = float(dt)
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
            where = (f"--step {self.dt!r}" if step is not None else
                     f"{scenario.path}:{scenario.events[-1].line}:1")
            raise CosimError(f"{where}: {n:.3g} communication steps of {self.dt!r} s from "
                             f"{scenario.start_time!r} s to {scenario.stop_time!r} s, more than "
                             f"the {MAX_STEPS} allowed")
        self._wire()

    # -- wiring -------------------------------------------------------------------------------
    def _wire(self) -> None:
        plant, ctrl, sc = self.plant, self.controller, self.scenario
        plant_in = {s.name for s in plant.inputs}
        plant_out = [s.name for s in plant.outputs]
        self.ctrl_outputs = [s.name for s in ctrl.outputs]
        self.refs = [s.name[4:] for s in ctrl.inputs if s.name.startswith("ref.")]
        self.measured = [s.name for s in ctrl.inputs if not s.name.startswith("ref.")]
        where = getattr(plant, "path", plant.name)
        units = {s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit}
        check = getattr(plant, "check_signals", None)
        if check is not None:
            check(self.ctrl_outputs, self.measured, units)
        for u in self.ctrl_outputs:
            if u not in plant_in:
                raise CosimError(f"{where}: controller output '{u}' is not an input of the plant"
                                 " (use --map to map it onto the plant's variable)")
        for y in self.measured:
            if y not in plant_out:
                raise CosimError(f"{where}: controller input '{y}' is not an output of the plant"
                                 " (use --map to map it onto the plant's variable)")
        settable = getattr(plant, "settable", None)
        at_start = settable(True) if settable else plant_in
        later = settable(False) if settable else plant_in
        sc.validate(at_start, self.refs, self.measured, driven=self.ctrl_outputs,
                    plant_tunable=later)
        given = {c.target for c in sc.columns_of(REF)}
        for r in self.refs:
            if r not in given:
                raise CosimError(f"{sc.path}:1:1: no column 'ref.{r}': the controller needs a "
                                 f"set-point for '{r}'")
        self.plant_outputs = plant_out
        self.refs_keys = [f"ref.{r}" for r in self.refs]
        self.scenario_plant = [c.target for c in sc.columns_of(PLANT)]
        self.use_sensor = bool(sc.columns_of(BIAS) or sc.columns_of(NOISE))

    def columns(self) -> list[str]:
        """Recorded columns, diagnostics excluded (they are appended as they appear).

        ``time``, ``ref.<o>`` (set-points), ``plant.<v>`` (plant inputs/parameters the scenario
        sets, then every plant output), ``sensor.<o>`` (measured values seen by the controller,
        only when the scenario perturbs them), ``ctrl.<u>`` (controller outputs, i.e. the plant
        inputs it drives), then ``ctrl.<d>`` per controller diagnostic.
        """
        cols = ["time"]
        cols += [f"{PREFIX_REF}.{r}" for r in self.refs]
        cols += [f"{PREFIX_PLANT}.{p}" for p in self.scenario_plant]
        cols += [f"{PREFIX_PLANT}.{y}" for y in self.plant_outputs]
        if self.use_sensor:
            cols += [f"{PREFIX_SENSOR}.{m}" for m in self.measured]
        cols += [f"{PREFIX_CTRL}.{u}" for u in self.ctrl_outputs]
        return cols

    # -- run ----------------------------------------------------------------------------------
    def run(self, on_step: Callable[[int], None] | None = None, *,
            record: RowSink | None = None, step_timeout: float | None = None,
            deadline: float | None = None) -> RunResult:
        """Run the scenario; never raises for a fault inside the run (see ``result.error``).

        Parameters
        ----------
        on_step : callable, optional
            Called with the number of completed plant steps after each step (progress bars).
        record : RowSink, optional
            Receives every row as it is recorded (``record.append(row, columns)``), e.g. a
            :class:`cosim.results.ResultsStream` that streams ``results.csv`` to disk. An
            exception it raises ends the run (status ``failed``).
        step_timeout : float, optional
            Wall-clock limit [s] of one controller step (``SIGALRM`` in the main thread, so a
            controller hung in Python code is stopped; elsewhere the step is measured after
            it returns). Plant steps are bounded by the plant itself (see
            :class:`cosim.isolated.IsolatedFmuComponent`).
        deadline : float, optional
            ``time.monotonic()`` value past which the run stops with status ``failed``
            (checked between steps: the whole-run timeout of campaigns).

        Raises
        ------
        CosimError
            Only for problems found before the first step.
        """
        if step_timeout is not None and not (math.isfinite(step_timeout) and step_timeout > 0):
            raise CosimError(f"--step-timeout {step_timeout!r}: expected a positive number of "
                             "seconds")
        run = _Run(self, record, step_timeout, deadline)
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


class RowSink(Protocol):
    """Where :meth:`Master.run` hands each recorded row (see ``record``)."""

    def append(self, row: list[float], columns: list[str]) -> None:
        """Take one row; ``columns`` names its cells (it grows when diagnostics appear)."""


class _Run:
    """One execution of a :class:`Master`: the loop state and the step phases.

    One communication step is :meth:`_apply_events`, :meth:`_measure` (plant outputs, the
    non-finite guard, the sensor), :meth:`_control` (the controller step, its timeout),
    :meth:`_record` and :meth:`_advance` (the plant step); :meth:`execute` maps what goes
    wrong in any of them onto the result's status.
    """

    def __init__(self, master: Master, record: RowSink | None, step_timeout: float | None,
                 deadline: float | None) -> None:
        self.m = master
        self.sink = record
        self.step_timeout = step_timeout
        self.deadline = deadline
        self.guard: interrupts.SignalGuard | None = None
        sc, ctrl = master.scenario, master.controller
        self.times = communication_times(sc.start_time, sc.stop_time, master.dt)
        self.base_cols = master.columns()
        self.result = RunResult(
            columns=list(self.base_cols), rows=[], steps_planned=len(self.times) - 1,
            step_size=master.dt, start_time=sc.start_time, stop_time=sc.stop_time,
            outputs=list(master.measured), references=list(master.refs),
            inputs=list(master.ctrl_outputs),
            bounds=dict(getattr(ctrl, "bounds", {}) or {}),
            units={s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit},
            perturbation_times=sc.perturbation_times())
        self.refs = {f"ref.{r}": math.nan for r in master.refs}
        self.held = dict.fromkeys(master.scenario_plant, math.nan)
        self.sensor = SensorModel(master.measured, seed=master.seed) if master.use_sensor \
            else None
        self.set_param = getattr(master.plant, "set_parameter", None)
        self.next_event = 0
        self.diag_names: list[str] = []
        self.diag_index: dict[str, int] = {}
        self.timing_names = sorted(getattr(ctrl, "timing_diagnostics", ()) or ())
        self.cin: dict[str, float] = {}
        self.u: dict[str, float] = {}
        self.diag: dict[str, float] = {}
        self.t = self.times[0]
        self.loop0: float | None = None

    # -- phases -------------------------------------------------------------------------------
    def _apply(self, event_values: tuple, started: bool) -> None:
        plant, sensor = self.m.plant, self.sensor
        for col, value in event_values:
            kind = col.kind
            if kind == REF:
                self.refs["ref." + col.target] = value
            elif kind == PLANT:
                self.held[col.target] = value
                if self.set_param is not None:
                    self.set_param(col.target, value)
                elif started:
                    plant.set_inputs({col.target: value})
            elif kind == BIAS:
                sensor.set_bias(col.target, value)  # type: ignore[union-attr]
            else:
                sensor.set_noise(col.target, value)  # type: ignore[union-attr]

    def _apply_events(self, t: float) -> None:
        events = self.m.scenario.events
        tol = 1e-9 * max(1.0, abs(t))
        while self.next_event < len(events) and events[self.next_event].time <= t + tol:
            self._apply(events[self.next_event].values, started=True)
            self.next_event += 1

    def _start(self) -> None:
        """Start values and first set-points, then set up plant and controller."""
        m, t = self.m, self.t
        self._apply(m.scenario.events[0].values, started=False)
        self.next_event = 1
        try:
            m.plant.setup(t)
            if self.set_param is None:
                m.plant.set_inputs({p: v for p, v in self.held.items() if not math.isnan(v)})
            m.controller.setup(t)
        except (CosimError, SimulationFailed):
            raise
        except Exception as exc:
            raise SimulationFailed(f"setup at t={t!r} failed: {exc}") from exc

    def _measure(self, t: float) -> tuple[dict[str, float], dict[str, float]]:
        """Plant outputs ``y(t)`` (all finite) and what the controller measures."""
        y = self.m.plant.get_outputs()
        if not all(map(math.isfinite, y.values())):
            bad = next(n for n in self.m.plant_outputs if not math.isfinite(y[n]))
            raise SimulationFailed(f"plant output '{bad}' is {y[bad]!r} at t={t!r}")
        sensor = self.sensor
        if sensor is None:
            return y, y
        sensor.set_inputs(y)
        sensor.step(t, self.m.dt)
        return y, sensor.get_outputs()

    def _control(self, t: float, ym: dict[str, float]) -> None:
        """The controller step: ``u`` and the diagnostics from ``y_m(t)`` and the set-points."""
        ctrl, cin, limit = self.m.controller, self.cin, self.step_timeout
        for name in self.m.measured:
            cin[name] = ym[name]
        cin.update(self.refs)
        fired: list[bool] = []
        t0 = _time.perf_counter()
        try:
            if limit is None:
                self._controller_step(t)
            else:
                with interrupts.alarm(limit) as fired:
                    self._controller_step(t)
        except (CosimError, SimulationFailed):
            raise
        except Exception as exc:
            if fired:
                raise self._timeout(t) from None
            raise SimulationFailed(f"controller '{ctrl.name}': step at t={t!r} failed: "
                                   f"{type(exc).__name__}: {exc}") from exc
        if fired or (limit is not None and _time.perf_counter() - t0 > limit):
            raise self._timeout(t)

    def _controller_step(self, t: float) -> None:
        ctrl = self.m.controller
        ctrl.set_inputs(self.cin)
        ctrl.step(t, self.m.dt * self.m.ratio)
        self.u = ctrl.get_outputs()
        diag = ctrl.diagnostics()
        if self.timing_names:
            diag = dict(diag)
            self.result.timing_rows.append(
                [t, *(_as_float(diag.pop(name, math.nan)) for name in self.timing_names)])
        self.diag = diag

    def _timeout(self, t: float) -> SimulationFailed:
        return SimulationFailed(f"controller '{self.m.controller.name}': step at t={t!r} took "
                                f"longer than the step timeout of {self.step_timeout:g} s")

    def _record(self, t: float, y: dict[str, float], ym: dict[str, float]) -> None:
        m = self.m
        row = [t]
        row += map(self.refs.__getitem__, m.refs_keys)
        row += map(self.held.__getitem__, m.scenario_plant)
        row += map(y.__getitem__, m.plant_outputs)
        if self.sensor is not None:
            row += map(ym.__getitem__, m.measured)
        row += map(self.u.__getitem__, m.ctrl_outputs)
        diag = self.diag
        if diag:
            names = self.diag_names
            if list(diag) == names:  # same diagnostics as before: fast path
                row += map(_as_float, diag.values())
            else:
                extra = [math.nan] * len(names)
                for key, value in diag.items():
                    j = self.diag_index.get(key)
                    if j is None:
                        j = self.diag_index[key] = len(names)
                        names.append(key)
                        extra.append(math.nan)
                        self.result.columns.append(f"{PREFIX_CTRL}.{key}")
                    extra[j] = _as_float(value)
                row += extra
        self.result.rows.append(row)
        if self.sink is not None:
            self.sink.append(row, self.result.columns)

    def _advance(self, k: int) -> None:
        """The plant step from ``t_k`` to ``t_k+1`` with ``u_k`` held."""
        plant, t = self.m.plant, self.times[k]
        plant.set_inputs(self.u)
        plant.step(t, self.times[k + 1] - t)

    def _check_interrupt(self) -> None:
        if self.guard is not None:
            self.guard.check()
        if self.deadline is not None and _time.monotonic() > self.deadline:
            raise SimulationFailed(f"run timeout: stopped at t={self.t!r} after "
                                   f"{self.result.steps} of {self.result.steps_planned} steps")

    # -- the loop -----------------------------------------------------------------------------
    def execute(self, on_step: Callable[[int], None] | None) -> None:
        """Run every step; map a fault or a signal onto the result (never raises)."""
        result, guard = self.result, self.guard
        wall0 = _time.perf_counter()
        try:
            with guard.raising() if guard is not None else contextlib.nullcontext():
                self._loop(on_step)
        except KeyboardInterrupt as exc:
            self._interrupted(exc)
        except (CosimError, SimulationFailed) as exc:
            self._failed(exc)
        except Exception as exc:  # a bug or an unexpected library error: keep the rows
            self._failed(SimulationFailed(f"at t={self.t!r}: {type(exc).__name__}: {exc}"))
        finally:
            result.wall_time_s = _time.perf_counter() - wall0
            if self.loop0 is not None:
                result.loop_time_s = _time.perf_counter() - self.loop0
            self._finish()

    def _loop(self, on_step: Callable[[int], None] | None) -> None:
        result, ratio, times = self.result, self.m.ratio, self.times
        n = len(times) - 1
        self._start()
        self.loop0 = _time.perf_counter()
        k = 0
        while True:
            self.t = t = times[k]
            self._apply_events(t)
            y, ym = self._measure(t)
            if k % ratio == 0:
                self._control(t, ym)
                self._check_interrupt()
            self._record(t, y, ym)
            if k == n:
                break
            self._advance(k)
            k += 1
            result.steps = k
            if on_step is not None:
                on_step(k)
            self._check_interrupt()

    def _interrupted(self, exc: KeyboardInterrupt) -> None:
        if not isinstance(exc, interrupts.Interrupted):
            exc = interrupts.Interrupted(signal.SIGINT)
        r = self.result
        r.status, r.error = "interrupted", exc
        r.reason = f"interrupted by {interrupts.signal_name(exc.signum)} at t={self.t!r}"

    def _failed(self, exc: CosimError) -> None:
        guard = self.guard
        if guard is not None and guard.signum is not None:
            # the signal reached library code (an FMU's doStep written in Python, a solver
            # callback) and came back as an error: the run was interrupted, not broken
            self._interrupted(interrupts.Interrupted(guard.signum))
            return
        r = self.result
        r.status, r.reason, r.error = "failed", str(exc), exc

    def _finish(self) -> None:
        """Controller summary, terminate both components, pad short rows."""
        result, m = self.result, self.m
        try:
            result.controller_summary = dict(m.controller.summary() or {})
        except Exception as exc:
            result.controller_summary = {"error": f"summary failed: {exc}"}
        for comp in (m.controller, m.plant):
            with contextlib.suppress(Exception):
                comp.terminate()
        if self.timing_names:
            result.timing_columns = ["time", *(f"{PREFIX_CTRL}.{d}" for d in self.timing_names)]
        width = len(result.columns)
        for row in result.rows:
            if len(row) < width:
                row.extend([math.nan] * (width - len(row)))


def _as_float(value: object) -> float:
    if value.__class__ is float:
        return value  # type: ignore[return-value]
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan
