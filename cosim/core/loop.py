"""One execution of a :class:`~cosim.core.master.Master`: the loop state and the step phases.

One communication step ``[t_k, t_k+1)`` is :meth:`Run._apply_events` (scenario events due at
``t_k``), the pacer's wait (:mod:`cosim.core.pacing`: nothing in simulated time, the sample's
instant on the wall clock), :meth:`Run._sample` (the plant's reading through its
:class:`~cosim.core.pacing.PlantIO`, the sensor, the controller step and its timeout, the
inputs written when the pacer allows it, or the pacer's answer to a stale reading; the row,
handed to the :class:`RowSink` and a :class:`~cosim.core.run_result.RunWatcher` too) and
:meth:`Run._advance` (the plant step); between two steps the watcher may act on the run
through its operator desk (:mod:`cosim.core.operator`);
:meth:`Run.execute` maps what goes wrong in any of them, or a signal, onto the result's
status and never raises. The same loop runs a plant FMU in simulated time and a live plant
on the wall clock: only the plant I/O and the pacer differ.
"""

from __future__ import annotations

import contextlib
import math
import signal
import time as _time
from collections.abc import Callable
from typing import TYPE_CHECKING

from cosim.core import interrupts
from cosim.core.component import Capability
from cosim.core.errors import CosimError, SimulationFailed
from cosim.core.run_result import (
    DEGRADED_SHARE,
    PREFIX_CTRL,
    RowSink,
    RunResult,
    RunWatcher,
    communication_times,
    shortfall_verdict,
)
from cosim.core.scenario import BIAS, DIST, OP, PLANT, REF, UNIFORM
from cosim.core.sensor import SensorModel

if TYPE_CHECKING:
    from cosim.core.master import Master

__all__ = ["RowSink", "Run"]


class Run:
    """One execution of a :class:`~cosim.core.master.Master` (see the module docstring).

    Attributes
    ----------
    io : PlantIO
        The plant's I/O (the master's).
    pacer : Pacer
        When samples happen (the master's).
    own_prefixes : tuple of str
        Diagnostics named ``<prefix>.<name>`` with one of these prefixes are the pacer's own
        columns, recorded under that name (a live run's ``live.fresh``); every other
        diagnostic is the controller's, recorded as ``ctrl.<name>``.
    """

    def __init__(self, master: Master, record: RowSink | None, step_timeout: float | None,
                 deadline: float | None, watch: RunWatcher | None = None) -> None:
        self.m = master
        self.watch = watch
        self.io = master.io
        self.pacer = master.pacer
        self.own_prefixes = master.pacer.own_prefixes
        self.sink = record
        self.step_timeout = step_timeout
        self.deadline = deadline
        # a controller in a worker process bounds its own steps (a SIGALRM cannot stop its
        # native code, nor reach a thread that is not the main one): it gets the limit
        self.alarm = step_timeout
        if master.controller.isolated:
            if step_timeout is not None:
                master.controller.timeout = step_timeout
            self.alarm = None
        self.guard: interrupts.SignalGuard | None = None
        sc, ctrl = master.scenario, master.controller
        self.times = communication_times(sc.start_time, sc.stop_time, master.dt)
        self.base_cols = master.columns()
        self.result = RunResult(
            columns=list(self.base_cols), rows=[], steps_planned=len(self.times) - 1,
            step_size=master.dt, start_time=sc.start_time, stop_time=sc.stop_time,
            outputs=list(master.measured), references=list(master.refs),
            inputs=list(master.ctrl_outputs),
            bounds=dict(ctrl.bounds),
            units={s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit},
            perturbation_times=sc.perturbation_times())
        self.refs = {f"ref.{r}": math.nan for r in master.refs}
        self.held = dict.fromkeys(master.scenario_plant, math.nan)
        self.dist = dict.fromkeys(master.dists, math.nan)
        self.sensor = SensorModel(master.measured, seed=master.seed) if master.use_sensor \
            else None
        plant = master.plant
        self.set_param = (plant.set_parameter if Capability.TUNABLE in plant.capabilities
                          else None)
        self.next_event = 0
        self.diag_names: list[str] = []
        self.diag_index: dict[str, int] = {}
        self.timing_names = sorted(ctrl.timing_diagnostics)
        self.cin: dict[str, float] = {}
        self.u: dict[str, float] = {}
        #: what the controller computed (``computed.<u>`` of an operator's controller; the
        #: inputs it wrote otherwise)
        self.computed: dict[str, float] = {}
        self.diag: dict[str, float] = {}
        #: the operator's desk (:mod:`cosim.core.operator`), its lock around each step
        self.desk = master.desk
        self.lock = self.desk.lock
        #: a controller an operator runs: what it computed is its ``computed.<u>``
        self.operated = Capability.OPERATOR in ctrl.capabilities
        self._first_ops: list[tuple] = []
        self.t = self.times[0]
        self.loop0: float | None = None

    # -- phases -------------------------------------------------------------------------------
    def _apply(self, event_values: tuple, started: bool) -> None:
        plant, sensor = self.m.plant, self.sensor
        for col, value in event_values:
            kind = col.kind
            if kind == REF:
                self.refs["ref." + col.target] = value
            elif kind == OP:   # after the controller's set-up at the first row
                if started:
                    self.desk.act(self.t, "scenario", col.target, value, "engineer")
                else:
                    self._first_ops.append((col, value))
            elif kind in (PLANT, DIST):
                (self.held if kind == PLANT else self.dist)[col.target] = value
                if self.set_param is not None:
                    self.set_param(col.target, value)
                elif started:
                    plant.set_inputs({col.target: value})
            elif kind == BIAS:
                sensor.set_bias(col.target, value)  # type: ignore[union-attr]
            elif kind == UNIFORM:
                sensor.set_uniform(col.target, value)  # type: ignore[union-attr]
            else:
                sensor.set_noise(col.target, value)  # type: ignore[union-attr]

    def _apply_events(self, t: float) -> None:
        events = self.m.scenario.events
        tol = 1e-9 * max(1.0, abs(t))
        with self.lock:
            while self.next_event < len(events) and events[self.next_event].time <= t + tol:
                self._apply(events[self.next_event].values, started=True)
                self.next_event += 1

    def _first_row(self) -> None:
        """The scenario's first row (set-points; plant values and disturbances, set on a
        plant with tunable parameters now, on its inputs once it is set up) and the
        disturbances' nominal values where the scenario has no column."""
        m = self.m
        self._apply(m.scenario.events[0].values, started=False)
        self.next_event = 1
        for d, value in m.dist_defaults.items():
            self.dist[d] = value
            if self.set_param is not None:
                self.set_param(d, value)

    def _setup_controller(self, t: float) -> None:
        """The controller told the run's set-points, set up at ``t``, and, when it knows
        measured disturbances ahead (``previewed``: ``preview = true``), given the
        scenario's value at any time of each it has a column of (the one that sets it)."""
        m, ctrl = self.m, self.m.controller
        if Capability.SETPOINTS in ctrl.capabilities:
            ctrl.expect_setpoints(m.scenario.setpoints())
        ctrl.setup(t)
        self.desk.attach(self.refs)   # the first row's operator actions, on the set-up one
        with self.lock:
            self._apply(tuple(self._first_ops), started=True)
        if Capability.PREVIEW not in ctrl.capabilities:
            return
        columns = {c.target for c in m.scenario.columns_of(DIST)}
        names = [d for d in ctrl.previewed if d in columns]
        if names:
            ctrl.set_schedule({d: m.scenario.schedule(DIST, d, self.dist[d]) for d in names})

    def _start(self) -> None:
        """Start values and first set-points, then set up plant and controller; the pacer
        starts."""
        m, t = self.m, self.t
        self._first_row()
        try:
            m.plant.setup(t)
            if self.set_param is None:
                self.io.start_values({**self.held, **self.dist})
            self._setup_controller(t)
        except (CosimError, SimulationFailed):
            raise
        except Exception as exc:
            raise SimulationFailed(f"setup at t={t!r} failed: {exc}") from exc
        self.pacer.start(self)
        if self.watch is not None:
            self.watch.start(self.result)

    def _sensed(self, t: float, y: dict[str, float]) -> dict[str, float]:
        """What the controller measures: ``y``, through the scenario's sensor model."""
        sensor = self.sensor
        if sensor is None:
            return y
        sensor.set_inputs(y)
        sensor.step(t, self.m.dt)
        return sensor.get_outputs()

    def _sample(self, k: int, t: float) -> None:
        """Read, control, write and record sample ``k`` at ``t``: a fresh reading steps the
        controller (every ``ratio`` samples) and its inputs are written when the pacer
        allows; a stale one is the pacer's to answer."""
        pacer = self.pacer
        reading = pacer.read(self, t)
        y = reading.values
        if self.io.reads_disturbances:
            for d in self.m.dists:
                self.dist[d] = y.get(d, math.nan)
        if reading.fresh:
            ym = self._sensed(t, y)
            if k % self.m.ratio == 0:
                u_prev = self.u
                self._control(t, ym)
                self._check_interrupt()
                if pacer.on_time():
                    pacer.written(self.io.write(self.u))
                else:   # too late: the previous inputs stay
                    self.u = u_prev or dict.fromkeys(self.m.ctrl_outputs, math.nan)
        else:
            ym = y
            pacer.stale(self, t, reading)
        pacer.sampled(self, t, reading)
        self._record(t, y, ym)
        self.desk.sampled(t, self.u, self.computed or self.u)

    def _control(self, t: float, ym: dict[str, float]) -> None:
        """The controller step: ``u`` and the diagnostics from ``y_m(t)`` and the set-points."""
        ctrl, cin, limit = self.m.controller, self.cin, self.alarm
        for name in self.m.measured:
            cin[name] = ym[name]
        cin.update(self.refs)
        for d in self.m.ctrl_dists:
            cin["dist." + d] = self.dist[d]
        fired: list[bool] = []
        t0 = _time.perf_counter()
        try:
            if limit is None:
                with self.lock:
                    self._controller_step(t)
            else:
                with interrupts.alarm(limit) as fired, self.lock:
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
        if self.operated:   # what it computed (in manual: in shadow)
            diag = dict(diag)
            self.computed = {u: _as_float(diag.pop(f"computed.{u}", self.u[u]))
                             for u in self.m.ctrl_outputs}
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
        row += map(self.dist.__getitem__, m.dists)
        row += map(self.held.__getitem__, m.scenario_plant)
        row += map(y.__getitem__, m.plant_outputs)
        if self.sensor is not None:
            row += map(ym.__getitem__, m.measured)
        row += map(self.u.__getitem__, m.ctrl_outputs)
        row += map((self.computed or self.u).__getitem__, m.ctrl_outputs)
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
                        own = key.split(".", 1)[0] in self.own_prefixes
                        self.result.columns.append(key if own else f"{PREFIX_CTRL}.{key}")
                    extra[j] = _as_float(value)
                row += extra
        guard = self.guard
        # a signal while the row is stored is recorded and raised after the step: raised
        # inside a sink's write, it would leave the row half written or written twice
        with guard.deferred() if guard is not None else contextlib.nullcontext():
            self.result.rows.append(row)
            if self.sink is not None:
                self.sink.append(row, self.result.columns)
            if self.watch is not None:
                self.watch.append(row, self.result.columns)
        if guard is not None:
            guard.check()

    def _advance(self, k: int) -> None:
        """The plant from ``t_k`` to ``t_k+1`` with ``u_k`` held."""
        t = self.times[k]
        self.io.advance(t, self.times[k + 1] - t)

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
            # named with the step it happened in; the cause keeps its traceback (a campaign
            # writes it to the run's traceback.txt)
            what = " ".join(f"{type(exc).__name__}: {exc}".split())
            failure = SimulationFailed(f"step {self.result.steps} (t = {self.t:.10g} s): {what}")
            failure.__cause__ = exc
            self._failed(failure)
        finally:
            result.wall_time_s = _time.perf_counter() - wall0
            if self.loop0 is not None:
                result.loop_time_s = _time.perf_counter() - self.loop0
            self._finish()

    def _loop(self, on_step: Callable[[int], None] | None) -> None:
        result, times, pacer = self.result, self.times, self.pacer
        n = len(times) - 1
        self._start()
        self.loop0 = _time.perf_counter()
        k = 0
        while True:
            self.t = t = times[k]
            self._apply_events(t)
            pacer.wait(k)
            self._sample(k, t)
            if k == n:
                break
            self._advance(k)
            k += 1
            result.steps = k
            if on_step is not None:
                on_step(k)
            if self.watch is not None:
                self._watched(times[k])
            self._check_interrupt()

    def _watched(self, t: float) -> None:
        """The watcher's turn before the sample at ``t`` (a page's requests, through the
        desk)."""
        self.watch.between(t)  # type: ignore[union-attr]

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
        verdict = shortfall_verdict(result.controller_summary)
        if result.status == "ok" and verdict is not None and verdict[0] > DEGRADED_SHARE:
            result.status, result.reason = "degraded", verdict[1]
        for comp in (m.controller, m.plant):
            with contextlib.suppress(Exception):
                comp.terminate()
        if self.timing_names:
            result.timing_columns = ["time", *(f"{PREFIX_CTRL}.{d}" for d in self.timing_names)]
        result.operator_rows = list(self.desk.rows)
        width = len(result.columns)
        for row in result.rows:
            if len(row) < width:
                row.extend([math.nan] * (width - len(row)))
        self.pacer.finish(self)


def _as_float(value: object) -> float:
    if value.__class__ is float:
        return value  # type: ignore[return-value]
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan
