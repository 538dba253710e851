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
import threading
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field

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
    def run(self, on_step: Callable[[int], None] | None = None) -> RunResult:
        """Run the scenario; never raises for a fault inside the run (see ``result.error``).

        Parameters
        ----------
        on_step : callable, optional
            Called with the number of completed plant steps after each step (progress bars).

        Raises
        ------
        CosimError
            Only for problems found before the first step.
        """
        sc, plant, ctrl = self.scenario, self.plant, self.controller
        times = communication_times(sc.start_time, sc.stop_time, self.dt)
        base_cols = self.columns()
        result = RunResult(
            columns=base_cols, rows=[], steps_planned=len(times) - 1, step_size=self.dt,
            start_time=sc.start_time, stop_time=sc.stop_time, outputs=list(self.measured),
            references=list(self.refs), inputs=list(self.ctrl_outputs),
            bounds=dict(getattr(ctrl, "bounds", {}) or {}),
            units={s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit},
            perturbation_times=sc.perturbation_times())
        refs = {f"ref.{r}": math.nan for r in self.refs}
        held = dict.fromkeys(self.scenario_plant, math.nan)
        sensor = SensorModel(self.measured, seed=self.seed) if self.use_sensor else None
        set_param = getattr(plant, "set_parameter", None)

        def apply(event_values: tuple, started: bool) -> None:
            for col, value in event_values:
                kind = col.kind
                if kind == REF:
                    refs["ref." + col.target] = value
                elif kind == PLANT:
                    held[col.target] = value
                    if set_param is not None:
                        set_param(col.target, value)
                    elif started:
                        plant.set_inputs({col.target: value})
                elif kind == BIAS:
                    sensor.set_bias(col.target, value)
                else:
                    sensor.set_noise(col.target, value)

        events = sc.events
        wall0 = _time.perf_counter()
        # first row: start values (before the plant is initialised), initial set-points
        apply(events[0].values, started=False)
        next_event = 1
        diag_names: list[str] = []
        diag_index: dict[str, int] = {}
        rows = result.rows
        timing_names = sorted(getattr(ctrl, "timing_diagnostics", ()) or ())
        timing_rows = result.timing_rows
        measured, ctrl_out, plant_out = self.measured, self.ctrl_outputs, self.plant_outputs
        ref_keys = list(refs)
        held_keys = list(held)
        cin: dict[str, float] = {}
        ratio = self.ratio
        isfinite = math.isfinite
        k = 0
        t = times[0]
        u: dict[str, float] = {}
        loop0: float | None = None
        # Ctrl-C raises KeyboardInterrupt as usual; the flag catches an interrupt that a
        # library swallowed (casadi turns one inside an IPOPT solve into a failed solve)
        interrupted: list[bool] = []
        previous_handler = None
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN):
            def on_sigint(signum: int, frame: object) -> None:
                interrupted.append(True)
                raise KeyboardInterrupt

            previous_handler = signal.signal(signal.SIGINT, on_sigint)
        try:
            try:
                plant.setup(t)
                if set_param is None:
                    plant.set_inputs({p: v for p, v in held.items() if not math.isnan(v)})
                ctrl.setup(t)
            except (CosimError, SimulationFailed):
                raise
            except Exception as exc:
                raise SimulationFailed(f"setup at t={t!r} failed: {exc}") from exc
            n = len(times) - 1
            loop0 = _time.perf_counter()
            while True:
                t = times[k]
                tol = 1e-9 * max(1.0, abs(t))
                while next_event < len(events) and events[next_event].time <= t + tol:
                    apply(events[next_event].values, started=True)
                    next_event += 1
                y = plant.get_outputs()
                if not all(map(isfinite, y.values())):
                    bad = next(n for n in plant_out if not isfinite(y[n]))
                    raise SimulationFailed(f"plant output '{bad}' is {y[bad]!r} at t={t!r}")
                if sensor is not None:
                    sensor.set_inputs(y)
                    sensor.step(t, self.dt)
                    ym = sensor.get_outputs()
                else:
                    ym = y
                if k % ratio == 0:
                    for name in measured:
                        cin[name] = ym[name]
                    cin.update(refs)
                    try:
                        ctrl.set_inputs(cin)
                        ctrl.step(t, self.dt * ratio)
                        u = ctrl.get_outputs()
                        diag = ctrl.diagnostics()
                        if timing_names:
                            diag = dict(diag)
                            timing_rows.append(
                                [t, *(_as_float(diag.pop(name, math.nan))
                                      for name in timing_names)])
                    except (CosimError, SimulationFailed):
                        raise
                    except Exception as exc:
                        raise SimulationFailed(
                            f"controller '{ctrl.name}': step at t={t!r} failed: "
                            f"{type(exc).__name__}: {exc}") from exc
                    if interrupted:
                        raise KeyboardInterrupt
                row = [t]
                row += map(refs.__getitem__, ref_keys)
                row += map(held.__getitem__, held_keys)
                row += map(y.__getitem__, plant_out)
                if sensor is not None:
                    row += map(ym.__getitem__, measured)
                row += map(u.__getitem__, ctrl_out)
                if diag:
                    if list(diag) == diag_names:  # same diagnostics as before: fast path
                        row += map(_as_float, diag.values())
                    else:
                        extra = [math.nan] * len(diag_names)
                        for key, value in diag.items():
                            j = diag_index.get(key)
                            if j is None:
                                j = diag_index[key] = len(diag_names)
                                diag_names.append(key)
                                extra.append(math.nan)
                            extra[j] = _as_float(value)
                        row += extra
                rows.append(row)
                if k == n:
                    break
                plant.set_inputs(u)
                plant.step(t, times[k + 1] - t)
                k += 1
                result.steps = k
                if on_step is not None:
                    on_step(k)
                if interrupted:
                    raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            result.status, result.reason, result.error = "interrupted", "interrupted", exc
        except (CosimError, SimulationFailed) as exc:
            result.status, result.reason, result.error = "failed", str(exc), exc
        except Exception as exc:  # a bug or an unexpected library error: keep the rows
            err = SimulationFailed(f"at t={t!r}: {type(exc).__name__}: {exc}")
            result.status, result.reason, result.error = "failed", str(err), err
        finally:
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
            result.wall_time_s = _time.perf_counter() - wall0
            if loop0 is not None:
                result.loop_time_s = _time.perf_counter() - loop0
            try:
                result.controller_summary = dict(ctrl.summary() or {})
            except Exception as exc:
                result.controller_summary = {"error": f"summary failed: {exc}"}
            for comp in (ctrl, plant):
                with contextlib.suppress(Exception):
                    comp.terminate()
        result.columns = base_cols + [f"{PREFIX_CTRL}.{d}" for d in diag_names]
        if timing_names:
            result.timing_columns = ["time", *(f"{PREFIX_CTRL}.{d}" for d in timing_names)]
        width = len(result.columns)
        for row in rows:
            if len(row) < width:
                row.extend([math.nan] * (width - len(row)))
        return result


def _as_float(value: object) -> float:
    if value.__class__ is float:
        return value  # type: ignore[return-value]
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan
