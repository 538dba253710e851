"""Campaigns on real Dask clusters: a local one, and a ``dask scheduler`` with two ``dask
worker`` processes started here on 127.0.0.1; the same per-run KPIs on both, resume after
SIGTERM, a plant that segfaults in some draws."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from cosim.campaign import run_campaign
from tests.cosim import pyfmu_models
from tests.toml_text import campaign_spec

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
#: Per-run columns that measure the machine, not the closed loop.
WALL_CLOCK = ("wall_time_s", "step_ms_p99")
SHORT = pyfmu_models.SHORT_SCENARIO


def engine_spec(tmp_path: Path) -> Path:
    """``tmp_path/spec.toml`` and its ``short.csv``: three runs of the robust MPC and the PI on
    drawn valve split, outlet area and sensor noise."""
    (tmp_path / "short.csv").write_text(SHORT)
    return campaign_spec(tmp_path, name="engine-test", runs=3, seed=11, scenario="short.csv",
                         controller="robust-mpc",
                         draw={"plant.gamma_b": {"uniform": [0.38, 0.42]},
                               "plant.a1": {"normal": [1.31e-4, 2e-6]},
                               "sensor.h1.noise": {"uniform": [0.0, 0.002]}},
                         variants=[{"name": "mpc"}, {"name": "pi", "controller": "pi"}])


def kpis(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=list(WALL_CLOCK)).sort_values(["run", "variant"]).reset_index(
        drop=True)


@pytest.fixture(scope="module")
def dask_scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1."""
    folder = tmp_path_factory.mktemp("dask")
    address_file = folder / "scheduler.json"
    dask = str(Path(sys.executable).with_name("dask"))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    procs = [subprocess.Popen(
        [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
         "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(address_file)],
        env=env, cwd=folder,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        end = time.monotonic() + 60
        while not address_file.exists():
            if time.monotonic() > end or procs[0].poll() is not None:
                pytest.fail("dask scheduler did not start")
            time.sleep(0.1)
        time.sleep(0.2)
        address = json.loads(address_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen(
            [dask, "worker", address, "--nworkers", "2", "--nthreads", "1", "--host",
             "127.0.0.1", "--no-dashboard", "--dashboard-address", "127.0.0.1:0"],
            env=env, cwd=folder,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in reversed(procs):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.mark.slow
def test_external_cluster_gives_the_local_engines_kpis(tmp_path: Path, dask_scheduler: str,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    spec = engine_spec(tmp_path)
    # the local workers' temporary folder is this test's own: other tests' campaigns, running
    # at the same time in other processes, do not show in it
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setenv("TMPDIR", str(private))
    monkeypatch.setattr(tempfile, "tempdir", None)
    local = run_campaign(spec, tmp_path / "local", workers=1)
    # the local workers removed the files they were sent when they ended
    assert not list(private.glob("cosim-campaign-*"))
    remote = run_campaign(spec, tmp_path / "remote", scheduler=dask_scheduler)
    assert local.status == remote.status == "ok"
    assert len(local.table) == 6 and set(local.table["variant"]) == {"mpc", "pi"}
    pd.testing.assert_frame_equal(kpis(local.table), kpis(remote.table))
    # every run's results.csv is the same file, whichever worker ran it
    for folder in sorted((tmp_path / "local" / "runs").iterdir()):
        other = tmp_path / "remote" / "runs" / folder.name
        assert (folder / "results.csv").read_bytes() == (other / "results.csv").read_bytes()
    # the outputs a campaign promises
    out = tmp_path / "local"
    assert {p.name for p in out.iterdir()} == {"campaign.json", "runs", "runs.parquet",
                                                "summary.json", "report.png"}
    table = pd.read_parquet(out / "runs.parquet")
    for column in ("run", "seed", "variant", "status", "reason", "plant.gamma_b", "plant.a1",
                   "sensor.h1.noise", "violation_count", "max_violation", "iae.h1", "iae.h2",
                   "worst_offset", "worst_offset.h1", "tv.qa", "tv.qb", "violations.h2.max",
                   "violations.qa.count", "fallbacks", "suboptimal_steps", "step_ms_p99",
                   "wall_time_s"):
        assert column in table.columns, column
    # both variants saw the same draws
    by_variant = table.set_index(["variant", "run"])
    assert list(by_variant.loc["mpc"]["plant.gamma_b"]) == list(
        by_variant.loc["pi"]["plant.gamma_b"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"] == 6 and summary["ok"] == 6 and summary["failed"] == 0
    assert summary["violation_probability_upper_95"] == pytest.approx(1 - 0.05 ** (1 / 6))
    assert set(summary["variants"]) == {"mpc", "pi"}
    assert summary["variants"]["mpc"]["quantiles"]["iae.h1"]["q50"] > 0


@pytest.mark.slow
def test_segfaulting_draws_fail_and_the_campaign_goes_on(tmp_path: Path,
                                                          pyfmu_dir: Path) -> None:
    spec = pyfmu_models.crashy_campaign(tmp_path, pyfmu_dir, runs=6, seed=1)
    result = run_campaign(spec, tmp_path / "out", workers=2)
    table = result.table.sort_values("run")
    crashed = table["plant.crash_at"] == 300.0
    assert 0 < crashed.sum() < 6
    assert list(table["status"]) == ["failed" if c else "ok" for c in crashed]
    assert all("killed its worker process in each of its 3 tries" in r
               for r in table[crashed]["reason"])
    # each crashing run was tried 3 times; the others, once (waiting on a worker that died
    # is no try)
    assert list(table["tries"]) == [3 if c else 1 for c in crashed]
    assert result.summary["retried_runs"] == crashed.sum()
    assert result.status == "failed"
    groups = result.summary["failures_by_reason"]
    assert len(groups) == 1 and next(iter(groups.values()))["count"] == crashed.sum()


@pytest.mark.slow
def test_sigterm_keeps_finished_runs_and_resume_runs_the_rest(tmp_path: Path,
                                                               pyfmu_dir: Path) -> None:
    spec = pyfmu_models.pi_campaign(tmp_path, pyfmu_dir / "Slow.fmu",
                                    {"sensor.h1.bias": {"uniform": [-0.01, 0.01]}},
                                    file="slow.toml", scenario="long.csv", runs=10)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    cmd = [sys.executable, "-m", "cosim.cli", "campaign", str(spec), "--out", str(out),
           "--workers", "1", "--quiet"]
    proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 120
    while len(list((out / "runs").glob("*/summary.json"))) < 2:
        assert time.monotonic() < end and proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == "cosim campaign: interrupted (SIGTERM)"
    kept = {p.parent.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*/summary.json")}
    assert 2 <= len(kept) < 10
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"] == len(kept) and summary["planned"] == 10
    # without --resume the folder is refused
    again = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True)
    assert again.returncode == 2 and "--resume" in again.stderr
    resumed = subprocess.run([*cmd, "--resume"], env=env, cwd=tmp_path, capture_output=True,
                             text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    table = pd.read_parquet(out / "runs.parquet")
    assert sorted(table["run"]) == list(range(10)) and set(table["status"]) == {"ok"}
    for name, mtime in kept.items():  # finished runs were not run again
        assert (out / "runs" / name / "summary.json").stat().st_mtime_ns == mtime
