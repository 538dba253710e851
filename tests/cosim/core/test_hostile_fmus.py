"""Every native part contained: hostile C FMUs (:mod:`tests.cosim.hostile`) as the controller
and as the plant of ``cosim run``, a Python run and a campaign.

From ``t = 500 s`` the FMU hangs, segfaults, aborts, calls ``exit(0)``, sends SIGTERM to its
own process group, or floods its output. A controller FMU always runs in a worker process of
its own, a plant FMU with ``--isolate``: each fault ends the run within the step timeout plus
a few seconds, exit 1, one line naming the FMU and what happened, ``results.csv`` with every
sample before the fault and a ``summary.json`` saying where it stopped; a flood changes
nothing the user sees; Ctrl-C and SIGTERM end a run stuck in native code at once. The runs
start in a session of their own, so that a fault that escaped its worker could not reach
pytest.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import cosim
from cosim.core.compare import read_table
from tests.cosim.core.test_run_faults import (
    ROOT,
    env_for,
    finish,
    leftovers,
    one_line,
    wait_for_rows,
)
from tests.cosim.hostile import FAULTS
from tests.toml_text import campaign_spec

#: 80 samples of 25 s; the faults start at t = 500 s (sample 20).
SCENARIO = "time,ref.h1,ref.h2\n0,0.6,0.6\n1000,0.7,0.7\n2000,,\n"
FAULT_TIME = 500.0
#: What each deadly fault says (the step timeout is 2 s).
DEATHS = {
    "hang": "took longer than the step timeout of 2 s (worker killed)",
    "segfault": "failed: worker died (signal 11, SIGSEGV)",
    "abort": "failed: worker died (signal 6, SIGABRT); it last printed: "
             "'hostile: giving up at t = 500 s'",
    "exit": "failed: worker died (exit code 0)",
    "signal": "failed: worker died (signal 15, SIGTERM)",
}


def _scenario(tmp_path: Path, plant_fault: str | None = None) -> Path:
    text = SCENARIO
    if plant_fault is not None:   # the hostile plant's fault: scenario columns at t = 0
        lines = text.splitlines()
        lines[0] += ",plant.fault,plant.fault_time"
        lines[1] += f",{FAULTS[plant_fault]},{FAULT_TIME}"
        lines[2:] = [line + ",," for line in lines[2:]]
        text = "\n".join(lines) + "\n"
    path = tmp_path / "sc.csv"
    path.write_text(text)
    return path


def _command(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", "run", *map(str, args), "--quiet"]


def _run(tmp_path: Path, *args: str | Path) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    proc = subprocess.run(_command(*args), env=env_for(tmp_path), cwd=ROOT, text=True,
                          capture_output=True, timeout=120, check=False,
                          start_new_session=True)
    return proc, time.monotonic() - t0


def _controller_args(hostile_dir: Path, fault: str) -> list[str | Path]:
    return ["--controller", hostile_dir / "HostileController.fmu", "--option",
            f"fault={FAULTS[fault]}", "--option", f"fault_time={FAULT_TIME}"]


def _stopped_at(out: Path, steps: int, last_time: float, reason: str) -> None:
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and reason in summary["reason"], summary["reason"]
    assert summary["steps"] == steps and summary["steps_planned"] == 80
    table = read_table(out / "results.csv")
    assert list(table.time) == [25.0 * k for k in range(len(table.time))]
    assert table.time[-1] == last_time


@pytest.mark.slow
@pytest.mark.parametrize("fault", list(DEATHS))
def test_a_hostile_controller_fmu_ends_the_run_in_one_line(fault: str, tmp_path: Path,
                                                           hostile_dir: Path) -> None:
    out = tmp_path / "out"
    proc, took = _run(tmp_path, _scenario(tmp_path), *_controller_args(hostile_dir, fault),
                      "--out", out, "--step-timeout", "2")
    assert proc.returncode == 1, proc.stderr
    what = f"controller FMU HostileController.fmu: doStep at t=500.0 {DEATHS[fault]}"
    assert what in one_line(proc.stderr) and proc.stdout == ""
    assert took < 2 + 20   # the timeout plus a few seconds (start-up included)
    # the controller step at t = 500 s failed: the samples before it are all there
    _stopped_at(out, 20, 475.0, what)
    assert leftovers(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize("fault", list(DEATHS))
def test_a_hostile_isolated_plant_ends_the_run_in_one_line(fault: str, tmp_path: Path,
                                                           hostile_dir: Path) -> None:
    out = tmp_path / "out"
    proc, took = _run(tmp_path, _scenario(tmp_path, fault), "--plant",
                      hostile_dir / "HostilePlant.fmu", "--controller", "pi", "--out", out,
                      "--step-timeout", "2")
    assert proc.returncode == 1, proc.stderr
    what = f"HostilePlant.fmu: doStep at t=500.0 {DEATHS[fault]}"
    assert what in one_line(proc.stderr) and proc.stdout == ""
    assert took < 2 + 20
    # the plant step from t = 500 s failed: the row at 500 s was recorded before it
    _stopped_at(out, 20, 500.0, what)
    assert leftovers(tmp_path) == []


@pytest.mark.slow
def test_a_flood_of_output_changes_nothing_the_user_sees(tmp_path: Path,
                                                         hostile_dir: Path) -> None:
    """Both FMUs write 1 MiB to standard output and log 200 warnings every step from 500 s
    on: the run ends ok, nothing reaches the terminal, and the results are those of quiet
    FMUs."""
    results = {}
    for name, fault in (("quiet", "none"), ("flood", "flood")):
        out = tmp_path / name
        proc, _ = _run(tmp_path, _scenario(tmp_path, fault), "--plant",
                       hostile_dir / "HostilePlant.fmu", "--isolate",
                       *_controller_args(hostile_dir, fault), "--out", out, "--no-figure")
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout == proc.stderr == ""
        table = read_table(out / "results.csv")
        results[name] = [list(table.time)] + [
            list(table.column(c)) for c in ("plant.h1", "plant.h2", "ctrl.qa", "ctrl.qb")]
    assert results["flood"] == results["quiet"]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_a_signal_ends_a_run_stuck_in_a_controller_fmu_at_once(
        sig: signal.Signals, tmp_path: Path, hostile_dir: Path) -> None:
    """No step timeout given: the controller FMU's own (60 s) would stop the hang; Ctrl-C or
    SIGTERM during it ends the run in a second or two, its exit code, its partial
    results."""
    out = tmp_path / "out"
    proc = subprocess.Popen(_command(_scenario(tmp_path), *_controller_args(hostile_dir, "hang"),
                                     "--out", out), env=env_for(tmp_path), cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wait_for_rows(out / "results.csv.part", 1, proc)
    time.sleep(2.0)   # the worker spins in doStep at t = 500 s
    t0 = time.monotonic()
    proc.send_signal(sig)
    code, err = finish(proc, timeout=30)
    assert time.monotonic() - t0 < 10
    assert code == 128 + sig, err
    assert one_line(err) == f"cosim run: interrupted ({sig.name})"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] == 20
    assert read_table(out / "results.csv").time[-1] == 475.0
    assert leftovers(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize(("fault", "what"), [
    ("hang", "controller 'pi': step at t=500.0 took longer than the step timeout of 2 s "
             "(worker killed)"),
    ("crash", "controller 'pi': step at t=500.0 failed: worker died (signal 11, SIGSEGV)")])
def test_a_python_controller_gone_wrong_in_native_code_is_contained(
        fault: str, what: str, tmp_path: Path, hostile_dir: Path) -> None:
    """``--step-timeout`` (``--isolate``) runs a Python controller in a worker too: stuck in
    a C loop (deaf to the SIGALRM that stops one stuck in Python) or crashing in native
    code, it ends the run as a hostile FMU does."""
    out = tmp_path / "out"
    proc, took = _run(tmp_path, _scenario(tmp_path), "--controller",
                      "tests.cosim.sleepy:NativePI", "--option", f'fault="{fault}"',
                      "--option", f"fault_at={FAULT_TIME}", "--option",
                      f'library="{hostile_dir / "libspin.so"}"', "--out", out,
                      "--step-timeout", "2")
    assert proc.returncode == 1, proc.stderr
    assert what in one_line(proc.stderr)
    assert took < 2 + 30
    _stopped_at(out, 20, 475.0, what)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["isolated"] is True and summary["controller"] == "tests.cosim.sleepy:NativePI"


def test_the_python_api_survives_a_crashing_controller_fmu(tmp_path: Path,
                                                           hostile_dir: Path) -> None:
    """``cosim.run`` in this very process: the controller FMU segfaults, the run fails with
    its rows, and this process goes on (a second run of the same FMU is healthy)."""
    fmu = str(hostile_dir / "HostileController.fmu")
    crashed = cosim.run(_scenario(tmp_path), controller=fmu,
                        options={"fault": FAULTS["segfault"], "fault_time": FAULT_TIME},
                        figure=False)
    assert crashed.status == "failed"
    assert "worker died (signal 11, SIGSEGV)" in crashed.reason
    assert len(crashed.result.rows) == 20
    healthy = cosim.run(_scenario(tmp_path), controller=fmu, figure=False)
    assert healthy.status == "ok" and len(healthy.result.rows) == 81


@pytest.mark.slow
def test_a_campaign_goes_on_past_a_crashing_controller_fmu(tmp_path: Path,
                                                           hostile_dir: Path) -> None:
    """On a real Dask worker: the variant whose controller FMU segfaults fails each run with
    the reason, the worker lives on (no run is tried again), the healthy variant's runs are
    ok."""
    (tmp_path / "Hostile.fmu").write_bytes((hostile_dir / "HostileController.fmu").read_bytes())
    _scenario(tmp_path)
    spec = campaign_spec(tmp_path, name="hostile", runs=2, seed=1, scenario="sc.csv",
                         controller="Hostile.fmu",
                         variants=[{"name": "healthy"}, {"name": "crashing", "options": {
                             "fault": FAULTS["segfault"], "fault_time": FAULT_TIME}}])
    result = cosim.run_campaign(spec, tmp_path / "out", workers=1)
    assert result.status != "ok"
    assert result.summary["retried_runs"] == 0 and set(result.table["tries"]) == {1}
    for run in range(2):
        for variant, status in (("healthy", "ok"), ("crashing", "failed")):
            summary = json.loads((tmp_path / "out" / "runs" / f"{run:06d}-{variant}"
                                  / "summary.json").read_text())
            assert summary["status"] == status, summary.get("reason")
            if status == "failed":
                assert "worker died (signal 11, SIGSEGV)" in summary["reason"]
                assert summary["steps"] == 20


@pytest.mark.slow
def test_a_campaign_with_isolate_goes_on_past_a_crashing_plant(tmp_path: Path,
                                                               hostile_dir: Path) -> None:
    """``isolate = true`` on a real Dask worker (a daemonic one may start the workers too):
    the plant FMU segfaults at 500 s in every run, each run fails alone with the reason, the
    Python controller (in a worker of its own) and the campaign go on."""
    (tmp_path / "Hostile.fmu").write_bytes((hostile_dir / "HostilePlant.fmu").read_bytes())
    _scenario(tmp_path, "segfault")
    spec = campaign_spec(tmp_path, name="hostile-plant", runs=3, seed=1, scenario="sc.csv",
                         plant="Hostile.fmu", controller="pi", isolate=True)
    result = cosim.run_campaign(spec, tmp_path / "out", workers=1)
    assert result.status != "ok"
    assert result.summary["retried_runs"] == 0 and set(result.table["tries"]) == {1}
    for run in range(3):
        summary = json.loads((tmp_path / "out" / "runs" / f"{run:06d}-pi" / "summary.json")
                             .read_text())
        assert summary["status"] == "failed" and summary["steps"] == 20
        assert "doStep at t=500.0 failed: worker died (signal 11, SIGSEGV)" in summary["reason"]
