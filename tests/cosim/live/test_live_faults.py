"""A live process fails as an FMU never does: each failure's documented answer, against a
real ``cosim serve-plant`` (its rehearsal switches, a restart, a slow controller, signals)."""

from __future__ import annotations

import json
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

import cosim
from cosim.live.runner import LiveOptions
from tests.cosim.live import ua
from tests.cosim.live.conftest import cosim as cli
from tests.cosim.live.conftest import env, served, start

SPEED = 250.0    # one sample every 0.1 s


def long_scenario(tmp_path: Path, samples: int) -> Path:
    path = tmp_path / "long.csv"
    path.write_text(f"time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n{25 * samples},,\n")
    return path


def rows_of(folder: Path) -> int:
    """The rows a run into ``folder`` has recorded so far (its ``results.csv.part``)."""
    part = folder / "results.csv.part"
    return max(len(part.read_text().splitlines()) - 1, 0) if part.exists() else 0


def later(delay: float, *actions: tuple, after: tuple[Path, int] | None = None
          ) -> threading.Thread:
    """Run ``actions`` ((seconds to wait, callable), ...) in a thread after ``delay``
    seconds, counted once the run into ``after[0]`` has recorded ``after[1]`` rows (a
    loaded machine may take seconds to start it)."""
    def body() -> None:
        end = time.monotonic() + 120
        while after is not None and rows_of(after[0]) < after[1] and time.monotonic() < end:
            time.sleep(0.02)
        time.sleep(delay)
        for wait, action in actions:
            action()
            time.sleep(wait)

    thread = threading.Thread(target=body, daemon=True)
    thread.start()
    return thread


@pytest.mark.slow
def test_bad_then_stale_measurements_hold_then_watchdog_safe_inputs(
        tmp_path: Path, safe_problem: Path) -> None:
    record = tmp_path / "plant.csv"
    notices: list[str] = []
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--problem",
                str(safe_problem), "--record", str(record)) as s:
        def flip(flag: str, value: bool) -> Callable[[], None]:
            return lambda: ua.write(s.endpoint, ["Simulation", flag], value)

        thread = later(0.0, (0.6, flip("BadOutputs", True)), (0.8, flip("BadOutputs", False)),
                       (0.6, flip("StaleOutputs", True)), (0.0, flip("StaleOutputs", False)),
                       after=(tmp_path / "run", 10))
        out = cosim.run(long_scenario(tmp_path, 70), plant=s.endpoint, controller="pi",
                        problem=safe_problem, out=tmp_path / "run", figure=False,
                        live=LiveOptions(speed=SPEED, watchdog=3), on_notice=notices.append)
        thread.join(10)
        assert ua.read(s.endpoint, ["qa"]).Value.Value == 0.0   # safe again at the end
    lv = out.summary["live"]
    assert out.status == "ok" and lv["stale"] >= 8, lv
    assert set(lv["stale_reasons"]) >= {"status BadSensorFailure", "older than a sample"}
    assert lv["watchdog_alarms"] == 2 and lv["safe_writes"] == lv["safe_tries"] == 2, lv
    assert lv["alarms"].startswith("2 watchdog alarms (at t = ") and lv["alarms"].count(
        "safe inputs qa = 0 m3/s written (qb holds)") == 2, lv["alarms"]
    assert lv["at_end"] == "safe inputs written", lv
    assert all(v <= lv["stale"] for v in lv["stale_reasons"].values())
    assert out.summary["kpis"]["iae"]["h1"] > 0      # the samples without a value skipped
    rows = pd.read_csv(tmp_path / "run" / "results.csv")
    assert (rows["live.fresh"] == 0).sum() == lv["stale"]
    stale = set(rows.index[rows["live.fresh"] == 0])
    # the two outages (a loaded machine may add a lone slow read, which the watchdog of 3
    # samples lets pass)
    starts = [i for i in sorted(stale) if i > 0 and i - 1 not in stale
              and {i + 1, i + 2} <= stale]
    assert len(starts) == 2, sorted(stale)
    safe = rows[rows["live.safe"] == 1]
    assert list(safe.index) == [i + 2 for i in starts] and (safe["plant.qa"] == 0.0).all()
    for i in starts:                                  # held, not written, before the alarm
        assert (rows.loc[i:i + 1, "live.written"] == 0).all()
        assert rows.loc[i + 1, "plant.qa"] == rows.loc[i - 1, "plant.qa"]
    assert (rows["live.fresh"].iloc[-10:] == 1).all()
    assert sum(n.startswith("alarm at t = ") and n.endswith(
        "; safe inputs qa = 0 m3/s written (qb holds)") for n in notices) == 2, notices
    assert sum(n.startswith("alarm cleared") for n in notices) == 2
    plant = pd.read_csv(record)
    assert (plant["ctrl.qa"] == 0.0).any()                 # the plant got the safe input


@pytest.mark.slow
def test_lost_connection_reconnects_and_resumes(tmp_path: Path, safe_problem: Path) -> None:
    """The plant's server stops, and comes back with its outputs stale for 4 s (longer than
    the reconnection's 2 s back-off: the run meets them stale): the watchdog's safe write
    fails while the link is down ("not yet written: link down, retrying"), is tried every
    stale sample, and reaches the plant once it is back (read back there); control resumes
    with fresh measurements."""
    args = ("--security", "None", "--speed", str(SPEED), "--problem", str(safe_problem))
    first = start(tmp_path, *args, name="first")
    servers = [first]
    notices: list[str] = []

    def restart() -> None:
        second = start(tmp_path, *args, "--record", str(tmp_path / "second.csv"),
                       port=first.port, name="second")
        servers.append(second)
        ua.write(second.endpoint, ["Simulation", "StaleOutputs"], True)

    def fresh_again() -> None:
        ua.write(servers[-1].endpoint, ["Simulation", "StaleOutputs"], False)

    thread = later(0.0, (0.3, first.stop), (4.0, restart), (0.0, fresh_again),
                   after=(tmp_path / "run", 12))
    try:   # (a loaded machine restarts a server slowly: no least share of control here)
        out = cosim.run(long_scenario(tmp_path, 180), plant=first.endpoint, controller="pi",
                        problem=safe_problem, figure=False, on_notice=notices.append,
                        out=tmp_path / "run",
                        live=LiveOptions(speed=SPEED, watchdog=5, min_controlled=0.0))
    finally:   # the restart may still be under way: bounded (30 s to listen, 20 s to write)
        thread.join(120)
        for server in servers:
            server.stop()
    lv = out.summary["live"]
    assert out.status == "ok" and lv["reconnects"] >= 1, lv
    assert "disconnected" in lv["stale_reasons"] and lv["watchdog_alarms"] >= 1
    alarm = next(n for n in notices if n.startswith("alarm at t = "))
    assert alarm.endswith("; safe inputs not yet written: link down, retrying"), alarm
    assert lv["safe_tries"] >= 10 and lv["safe_writes"] >= 1, lv
    assert any(n.startswith("safe inputs qa = 0 m3/s written (qb holds)") or
               n.endswith("; safe inputs qa = 0 m3/s written (qb holds)") for n in notices)
    plant = pd.read_csv(tmp_path / "second.csv")
    assert (plant["ctrl.qa"] == 0.0).any()               # the restarted plant got it
    fresh = out.to_pandas()["live.fresh"].to_numpy()
    assert fresh[:10].sum() >= 9 and fresh[-20:].all() and not fresh.all()


@pytest.mark.slow
def test_step_past_its_deadline_keeps_the_previous_inputs(tmp_path: Path) -> None:
    record = tmp_path / "plant.csv"
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--frozen", "--record",
                str(record)) as s:
        out = cosim.run(long_scenario(tmp_path, 30), plant=s.endpoint,
                        controller="tests.cosim.sleepy:SleepyPI", figure=False,
                        options={"hang_at": 500.0, "hang": 0.09},
                        live=LiveOptions(speed=SPEED))
        time.sleep(0.3)
    lv = out.summary["live"]
    rows = out.to_pandas()
    late = rows[rows["time"] >= 500.0]
    assert lv["deadline_misses"] == len(late) and (late["live.on_time"] == 0).all()
    assert (late["live.written"] == 0).all()
    before = rows[rows["time"] < 500.0]["plant.qa"].iloc[-1]
    assert (late["plant.qa"] == before).all()            # recorded: what the plant kept
    plant = pd.read_csv(record)
    assert (plant[plant["time"] >= 500.0]["ctrl.qa"] == before).all()


@pytest.mark.slow
def test_written_values_never_leave_the_box(tmp_path: Path, short_scenario: Path) -> None:
    record = tmp_path / "plant.csv"
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--record",
                str(record)) as s:
        out = cosim.run(short_scenario, plant=s.endpoint, figure=False,
                        controller="tests.cosim.sleepy:GreedyPI", options={"factor": 3.0},
                        live=LiveOptions(speed=SPEED))
        time.sleep(0.3)
    assert out.summary["live"]["clipped"] > 0
    plant = pd.read_csv(record)
    assert plant["ctrl.qa"].between(0.0, 9.05e-4).all()
    assert plant["ctrl.qb"].between(0.0, 11.1e-4).all() and (plant["ctrl.qb"] == 11.1e-4).any()
    assert "outside its box" not in s.stderr() and "0 clipped inputs" in s.stderr()


@pytest.mark.slow
@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_signal_writes_safe_inputs_and_keeps_the_rows(tmp_path: Path, safe_problem: Path,
                                                      signum: int, code: int) -> None:
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--problem",
                str(safe_problem)) as s:
        out = tmp_path / "run"
        proc = subprocess.Popen(cli("run", str(long_scenario(tmp_path, 400)), "--plant",
                                    s.endpoint, "--security", "None", "--speed", str(SPEED),
                                    "--controller", "pi", "--problem", str(safe_problem),
                                    "--out", str(out), "--quiet"),
                                env=env(), cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        end = time.monotonic() + 60
        while not (out / "results.csv.part").exists() or \
                len((out / "results.csv.part").read_text().splitlines()) < 20:
            assert time.monotonic() < end and proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        assert ua.read(s.endpoint, ["qa"]).Value.Value != 0.0
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == code, err
        assert ua.read(s.endpoint, ["qa"]).Value.Value == 0.0     # the safe input
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] >= 19
    assert len(pd.read_csv(out / "results.csv")) in (summary["steps"], summary["steps"] + 1)
    assert "Traceback" not in err


@pytest.mark.slow
def test_measured_disturbance_is_read_from_the_plant(tmp_path: Path) -> None:
    """The heater with a measured ambient temperature and a dead time: the run reads the
    disturbance the plant measures (a rehearsal changes it on the served plant)."""
    from tests import example_builds as examples

    fmu = examples.build("heater_dead_time", tmp_path / "fmu")
    problem = examples.problem_file("heater_dead_time")
    scenario = tmp_path / "heat.csv"
    scenario.write_text("time,ref.T\n0,40\n1200,\n")
    record = tmp_path / "plant.csv"
    with served(tmp_path, str(fmu), "--problem", str(problem), "--security", "None",
                "--speed", "200", "--record", str(record)) as s:
        folder = "heater_dead_time"

        def cold() -> None:
            from asyncua import ua as uat

            async def action(client: Any, _: Any) -> None:
                node = await client.nodes.objects.get_child([f"2:{folder}", "2:T_in"])
                await node.write_value(uat.DataValue(uat.Variant(10.0, uat.VariantType.Double)))

            ua.call(s.endpoint, action, folder_name=folder)

        thread = later(0.5, (0.0, cold), after=(tmp_path / "run", 5))
        out = cosim.run(scenario, plant=s.endpoint, problem=problem, figure=False,
                        controller="tests.cosim.live.controllers:AmbientP",
                        out=tmp_path / "run", live=LiveOptions(speed=200))
        thread.join(10)
    rows = out.to_pandas()
    assert out.status == "ok" and out.summary["live"]["stale"] == 0
    d = rows["dist.T_in"].to_numpy()
    assert d[0] != 10.0 and d[-1] == 10.0
    k = int((d == 10.0).argmax())
    ff = 50.0 * (20.0 - rows["dist.T_in"])     # the controller used what it measured
    p = (100.0 * (rows["ref.T"] - rows["plant.T"]) + ff).clip(0.0, 2000.0)
    assert (rows["ctrl.P"] - p).abs().max() < 1e-9 and rows["ctrl.P"].iloc[k] > 0
    plant = pd.read_csv(record)
    assert (plant["dist.T_in"].iloc[-5:] == 10.0).all()
