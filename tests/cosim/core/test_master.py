"""The master: timing, wiring by name, scenario events, sensor, recording, faults."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

from cosim.adapters.pi import PIController
from cosim.core.component import Component, Signal
from cosim.core.errors import CosimError, SimulationFailed
from cosim.core.fmu import FmuComponent
from cosim.core.master import Master, communication_times
from cosim.core.scenario import load


def scenario(tmp_path: Path, text: str) -> object:
    path = tmp_path / "sc.csv"
    path.write_text(text)
    return load(path)


def table(result: object) -> dict[str, np.ndarray]:
    data = np.asarray(result.rows)
    return {c: data[:, i] for i, c in enumerate(result.columns)}


class Recorder(Component):
    """A controller that applies constant inputs and remembers what it was given, when."""

    direct_feedthrough = True
    sample_time = 25.0

    def __init__(self, fail_at: float | None = None) -> None:
        self.name = "rec"
        self.inputs = (Signal("h1", "m"), Signal("ref.h1", "m"))
        self.outputs = (Signal("qa", "m3/s"), Signal("qb", "m3/s"))
        self.seen: list[tuple[float, dict[str, float]]] = []
        self.fail_at = fail_at
        self.terminated = 0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._in = dict(values)

    def step(self, t: float, dt: float) -> None:
        if self.fail_at is not None and t >= self.fail_at:
            raise ZeroDivisionError("boom")
        self.seen.append((t, dict(self._in)))

    def get_outputs(self) -> dict[str, float]:
        return {"qa": 5e-4, "qb": 5e-4}

    def diagnostics(self) -> dict[str, float]:
        n = len(self.seen)
        return {"calls": n} if n < 3 else {"calls": n, "late": 1.0}

    def summary(self) -> dict:
        return {"calls": len(self.seen)}

    def terminate(self) -> None:
        self.terminated += 1


def test_communication_times() -> None:
    assert communication_times(0.0, 100.0, 25.0) == [0.0, 25.0, 50.0, 75.0, 100.0]
    assert communication_times(0.0, 110.0, 25.0)[-2:] == [100.0, 110.0]
    t = communication_times(0.0, 37500.0, 25.0)
    assert len(t) == 1501 and t[-1] == 37500.0


def test_events_sensor_and_recording(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1,plant.qd1,plant.a1,sensor.h1.bias\n"
                            "0,0.7,0,,0\n100,0.9,-1e-5,,\n160,,,1e-4,0.05\n250,,,,\n")
    ctrl = Recorder()
    result = Master(FmuComponent(fmu2_path), ctrl, sc).run()
    assert result.status == "ok" and result.error is None
    assert result.steps == result.steps_planned == 10
    assert result.columns == ["time", "ref.h1", "plant.qd1", "plant.a1", "plant.h1", "plant.h2",
                              "plant.h3", "plant.h4", "sensor.h1", "plant.qa", "plant.qb",
                              "ctrl.qa", "ctrl.qb", "ctrl.calls", "ctrl.late"]
    c = table(result)
    assert list(c["time"]) == [25.0 * k for k in range(11)]
    # set-point and leak change exactly at t = 100; the 160 s event waits for t = 175
    assert list(c["ref.h1"]) == [0.7] * 4 + [0.9] * 7
    assert list(c["plant.qd1"]) == [0.0] * 4 + [-1e-5] * 7
    assert math.isnan(c["plant.a1"][0]) and c["plant.a1"][7] == 1e-4
    bias = c["sensor.h1"] - c["plant.h1"]
    assert np.all(bias[:7] == 0.0) and np.allclose(bias[7:], 0.05, atol=1e-15)
    # the controller saw the measured value and the set-point of the same instant
    assert [s["h1"] for _, s in ctrl.seen] == list(c["sensor.h1"])
    assert [s["ref.h1"] for _, s in ctrl.seen] == list(c["ref.h1"])
    # diagnostics that appear later are back-filled with NaN
    assert list(c["ctrl.calls"]) == list(range(1, 12))
    assert np.isnan(c["ctrl.late"][:2]).all() and (c["ctrl.late"][2:] == 1.0).all()
    assert result.controller_summary == {"calls": 11}
    assert ctrl.terminated == 1
    assert result.perturbation_times == [100.0, 160.0]


def test_zero_order_hold_against_a_bare_loop(tmp_path: Path, fmu2_path: Path) -> None:
    """Master + PI = the same loop written by hand: plant(t) → PI → plant step."""
    sc = scenario(tmp_path, "time,ref.h1,ref.h2\n0,0.9,0.8\n500,,\n")
    result = Master(FmuComponent(fmu2_path), PIController(), sc).run()
    plant, pi = FmuComponent(fmu2_path), PIController()
    plant.setup(0.0)
    h1 = []
    for k in range(21):
        y = plant.get_outputs()
        h1.append(y["h1"])
        pi.set_inputs({**y, "ref.h1": 0.9, "ref.h2": 0.8})
        pi.step(25.0 * k, 25.0)
        if k < 20:
            plant.set_inputs(pi.get_outputs())
            plant.step(25.0 * k, 25.0)
    plant.terminate()
    assert list(table(result)["plant.h1"]) == h1


def test_noise_is_seeded(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1,sensor.h1.noise\n0,0.7,0.01\n500,,\n")

    def noise(seed: int) -> np.ndarray:
        c = table(Master(FmuComponent(fmu2_path), Recorder(), sc, seed=seed).run())
        return c["sensor.h1"] - c["plant.h1"]

    a, b, other = noise(1), noise(1), noise(2)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, other)
    assert 0.003 < a.std() < 0.03


def test_wiring_errors(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n100,\n")

    class Bad(Recorder):
        def __init__(self) -> None:
            super().__init__()
            self.outputs = (Signal("valve"),)

    with pytest.raises(CosimError, match=r"FourTank.fmu: signal 'valve' \(not in a variable map\)"
                                         r": the FMU has no such variable \(map it with --map\)"):
        Master(FmuComponent(fmu2_path), Bad(), sc)
    no_ref = scenario(tmp_path, "time,plant.qd1\n0,0\n100,\n")
    with pytest.raises(CosimError, match=r"sc.csv:1:1: no column 'ref.h1'"):
        Master(FmuComponent(fmu2_path), Recorder(), no_ref)
    unknown = scenario(tmp_path, "time,ref.h1,plant.valve\n0,0.7,1\n100,,\n")
    with pytest.raises(CosimError, match=r"sc.csv:1:3: unknown plant variable 'plant.valve'"):
        Master(FmuComponent(fmu2_path), Recorder(), unknown)
    with pytest.raises(CosimError, match="does not divide"):
        Master(FmuComponent(fmu2_path), Recorder(), sc, step=10.0)


def test_multirate_controller_is_held(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n100,\n")
    ctrl = Recorder()
    result = Master(FmuComponent(fmu2_path), ctrl, sc, step=5.0).run()
    assert result.steps == 20
    assert [t for t, _ in ctrl.seen] == [0.0, 25.0, 50.0, 75.0, 100.0]


def test_controller_exception_keeps_rows(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")
    ctrl = Recorder(fail_at=300.0)
    result = Master(FmuComponent(fmu2_path), ctrl, sc).run()
    assert result.status == "failed" and isinstance(result.error, SimulationFailed)
    assert "controller 'rec': step at t=300.0 failed: ZeroDivisionError: boom" in result.reason
    assert len(result.rows) == 12 and result.rows[-1][0] == 275.0
    assert result.steps == 12
    assert ctrl.terminated == 1


def test_fmu_failure_keeps_rows(tmp_path: Path, pyfmu_dir: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")
    result = Master(FmuComponent(pyfmu_dir / "Failing.fmu"), Recorder(), sc).run()
    assert result.status == "failed"
    assert result.reason.startswith("Failing.fmu: doStep at t=500.0 failed")
    assert result.steps == 20 and len(result.rows) == 21 and result.rows[-1][0] == 500.0


def test_interrupt_keeps_rows(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")

    class Impatient(Recorder):
        def step(self, t: float, dt: float) -> None:
            if t >= 100.0:
                raise KeyboardInterrupt
            super().step(t, dt)

    result = Master(FmuComponent(fmu2_path), Impatient(), sc).run()
    assert result.status == "interrupted" and isinstance(result.error, KeyboardInterrupt)
    assert [row[0] for row in result.rows] == [0.0, 25.0, 50.0, 75.0]


class TimedRecorder(Recorder):
    """A controller that also reports a wall-clock diagnostic."""

    timing_diagnostics = frozenset({"step_ms"})

    def diagnostics(self) -> dict[str, float]:
        return {"calls": len(self.seen), "step_ms": 1000.0 * len(self.seen) + 0.5}


def test_timing_diagnostics_are_kept_out_of_results(tmp_path: Path, fmu2_path: Path) -> None:
    from cosim.core import results

    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n100,\n")
    result = Master(FmuComponent(fmu2_path), TimedRecorder(), sc).run()
    assert "ctrl.step_ms" not in result.columns and "ctrl.calls" in result.columns
    assert result.timing_columns == ["time", "ctrl.step_ms"]
    assert result.timing_rows == [[25.0 * k, 1000.0 * (k + 1) + 0.5] for k in range(5)]
    results.write(tmp_path / "out", result, figure=False)
    timings = (tmp_path / "out" / "timings.csv").read_text().splitlines()
    assert timings[0] == '"time","ctrl.step_ms"' and timings[1] == "0.0,1000.5"
    assert "step_ms" not in (tmp_path / "out" / "results.csv").read_text()


class SwallowsInterrupt(Recorder):
    """Like casadi in an IPOPT solve: Ctrl-C arrives inside ``step``, which swallows it."""

    def step(self, t: float, dt: float) -> None:
        import contextlib
        import os
        import signal

        super().step(t, dt)
        if t == 100.0:
            # swallowed: the solve "fails" and the controller carries on
            with contextlib.suppress(KeyboardInterrupt):
                os.kill(os.getpid(), signal.SIGINT)


def test_interrupt_swallowed_by_the_controller_still_stops_the_run(tmp_path: Path,
                                                                    fmu2_path: Path) -> None:
    import signal

    handler = signal.getsignal(signal.SIGINT)
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")
    ctrl = SwallowsInterrupt()
    result = Master(FmuComponent(fmu2_path), ctrl, sc).run()
    assert result.status == "interrupted" and isinstance(result.error, KeyboardInterrupt)
    # rows up to t = 75 s are kept; the step whose solve was interrupted is not recorded
    assert [row[0] for row in result.rows] == [0.0, 25.0, 50.0, 75.0]
    assert signal.getsignal(signal.SIGINT) is handler and ctrl.terminated == 1


def test_step_and_seed_are_checked(tmp_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n100,\n")
    for step in (-1.0, 0.0, math.nan, math.inf):
        with pytest.raises(CosimError, match="must be a positive, finite number"):
            Master(Recorder(), Recorder(), sc, step=step)
    with pytest.raises(CosimError, match=r"^seed must be a non-negative integer, got -1"):
        Master(Recorder(), Recorder(), sc, seed=-1)


def test_uniform_noise_is_bounded_and_seeded(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1,sensor.h1.uniform\n0,0.7,0.02\n2500,,\n")

    def noise(seed: int) -> np.ndarray:
        c = table(Master(FmuComponent(fmu2_path), Recorder(), sc, seed=seed).run())
        return c["sensor.h1"] - c["plant.h1"]

    a, b = noise(3), noise(3)
    assert np.array_equal(a, b) and not np.array_equal(a, noise(4))
    assert np.max(np.abs(a)) <= 0.02 and np.max(a) > 0.015 and np.min(a) < -0.015


def test_a_stream_gets_every_row_as_it_is_recorded(tmp_path: Path, fmu2_path: Path) -> None:
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n200,\n")
    seen: list[tuple[int, int]] = []

    class Sink:
        def append(self, row: list[float], columns: list[str]) -> None:
            seen.append((len(row), len(columns)))

    result = Master(FmuComponent(fmu2_path), Recorder(), sc).run(record=Sink())
    assert len(seen) == len(result.rows) == 9
    # the columns grow when a diagnostic appears (``late`` from the third step)
    assert seen[0] == (seen[0][1], seen[0][1]) and seen[-1][1] == seen[0][1] + 1


def test_run_deadline_stops_between_steps(tmp_path: Path, fmu2_path: Path) -> None:
    import time

    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")
    result = Master(FmuComponent(fmu2_path), Recorder(), sc).run(deadline=time.monotonic())
    assert result.status == "failed" and result.reason.startswith("run timeout")
    assert result.steps < 40


def test_a_signal_inside_the_stream_write_neither_cuts_nor_repeats_rows(
        tmp_path: Path, fmu2_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGTERM arriving while the streamed rows are being written (the CI failure of stop 13:
    the rows of one flush were written twice, and results.csv went back in time)."""
    import os
    import signal

    from cosim.core.results import ResultsStream

    class SteadyRecorder(Recorder):  # the same columns throughout: the stream is kept
        def diagnostics(self) -> dict[str, float]:
            return {"calls": len(self.seen)}

    stream = ResultsStream(tmp_path / "results.csv", flush_interval=0.0)
    fsync = os.fsync

    def fsync_then_signal(fd: int) -> None:
        fsync(fd)
        if len(calls) == 4:
            os.kill(os.getpid(), signal.SIGTERM)  # the handler runs here, mid-flush
        calls.append(fd)

    calls: list[int] = []
    monkeypatch.setattr(os, "fsync", fsync_then_signal)
    sc = scenario(tmp_path, "time,ref.h1\n0,0.7\n1000,\n")
    result = Master(FmuComponent(fmu2_path), SteadyRecorder(), sc).run(record=stream)
    monkeypatch.undo()
    assert result.status == "interrupted" and "SIGTERM" in result.reason
    stream.finish(result.columns, result.rows)
    lines = (tmp_path / "results.csv").read_text().splitlines()[1:]
    assert [float(line.split(",")[0]) for line in lines] == [row[0] for row in result.rows]
    assert [row[0] for row in result.rows] == [0.0, 25.0, 50.0, 75.0, 100.0]
