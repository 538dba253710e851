"""Campaigns on the Dask deployments users run, against the local engine on the same draws.

Each test starts a real ``dask scheduler`` and real ``dask worker`` processes on 127.0.0.1
(dashboards off), waits for each of them a bounded time, and stops them at teardown
(SIGTERM to each process group it started, then SIGKILL), also when the test fails. The same
small campaign (drawn valve split, outlet area and sensor bias; two robust-MPC variants on a
2,000 s scenario) runs on:

* one worker process with two threads (``--nworkers 1 --nthreads 2``: Dask's own shape),
  where two runs share a process at the same time;
* two single-thread worker processes;
* a scheduler without workers, the worker joining after the campaign started;

and every run's KPIs (and its ``results.csv``, byte for byte) equal the local engine's.
A worker process killed with SIGKILL while it runs gets its run retried on another worker;
a run that kills its worker every time is recorded as failed after the last try.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from cosim.campaign import run_campaign
from cosim.campaign.engine import MAX_TRIES
from tests.cosim import pyfmu_models
from tests.cosim.pyfmu_models import pi_campaign
from tests.toml_text import campaign_spec

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
DASK = str(Path(sys.executable).with_name("dask"))
#: Per-run columns that measure the machine (or the deployment), not the closed loop.
NOT_COMPARED = ("wall_time_s", "step_ms_p99", "tries")
#: Bound of every wait for a process or a campaign [s].
WAIT = 240.0

SHORT = pyfmu_models.SHORT_SCENARIO


def mpc_spec(folder: Path) -> Path:
    """The MPC campaign, ``folder/spec.toml`` and its ``short.csv``: drawn valve split, outlet
    area and sensor bias; the tracking law and the paper's (its own kernel and workspace)."""
    (folder / "short.csv").write_text(SHORT)
    return campaign_spec(folder, name="deployments", runs=5, seed=5, scenario="short.csv",
                         controller="robust-mpc",
                         draw={"plant.gamma_a": {"uniform": [0.28, 0.32]},
                               "plant.a1": {"normal": [1.31e-4, 2e-6]},
                               "sensor.h1.bias": {"uniform": [-0.01, 0.01]}},
                         variants=[{"name": "mpc"},
                                   {"name": "mpc-paper", "options": {"law": "paper"}}])


class Cluster:
    """A ``dask scheduler`` and ``dask worker`` processes started here, on 127.0.0.1."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        # the workers' temporary folders (the campaign's files; those of a killed worker stay
        # behind) go into the test's folder
        (folder / "tmp").mkdir(exist_ok=True)
        self.env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(ROOT), os.environ.get("PYTHONPATH", "")]), TMPDIR=str(folder / "tmp"))
        self.procs: list[subprocess.Popen] = []
        self.address = ""

    def _start(self, args: list[str], env: dict[str, str], log: str) -> subprocess.Popen:
        with open(self.folder / log, "wb") as out:
            # a session of its own: teardown ends the process and every child it started
            proc = subprocess.Popen([DASK, *args], env=env, cwd=self.folder, stdout=out,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append(proc)
        return proc

    def start_scheduler(self, extra_env: dict[str, str] | None = None) -> str:
        """``dask scheduler`` (environment ``extra_env`` added); waits for its address."""
        address_file = self.folder / "scheduler.json"
        proc = self._start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                            "--scheduler-file", str(address_file)],
                           dict(self.env, **(extra_env or {})), "scheduler.log")
        end = time.monotonic() + WAIT
        while True:
            with contextlib.suppress(OSError, ValueError, KeyError):
                address = json.loads(address_file.read_text())["address"]
                break
            assert proc.poll() is None, self.log("scheduler.log")
            assert time.monotonic() < end, "dask scheduler did not start"
            time.sleep(0.1)
        assert address.startswith("tcp://127.0.0.1:"), address
        self.address = address
        return address

    def add_worker(self, nworkers: int, nthreads: int) -> subprocess.Popen:
        """``dask worker ADDRESS --nworkers N --nthreads T`` (does not wait for it)."""
        n = len(self.procs)
        return self._start(["worker", self.address, "--nworkers", str(nworkers), "--nthreads",
                            str(nthreads), "--host", "127.0.0.1", "--no-dashboard"],
                           self.env, f"worker{n}.log")

    def wait_for_workers(self, n: int) -> dict[str, int]:
        """Wait (bounded) until ``n`` worker processes are connected; their threads."""
        from distributed import Client

        with Client(self.address, timeout="30s") as client:
            client.wait_for_workers(n, timeout=WAIT)
            return client.nthreads()

    def log(self, name: str) -> str:
        with contextlib.suppress(OSError):
            return (self.folder / name).read_text(errors="replace")[-3000:]
        return ""

    def stop(self) -> None:
        """SIGTERM to every process group started here, then SIGKILL after 20 s."""
        for proc in reversed(self.procs):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in reversed(self.procs):
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=20)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=10)


@contextlib.contextmanager
def started(folder: Path, scheduler_env: dict[str, str] | None = None) -> Iterator[Cluster]:
    """A :class:`Cluster` with its scheduler (no workers yet), stopped at the end."""
    c = Cluster(folder)
    try:
        c.start_scheduler(scheduler_env)
        yield c
    finally:
        c.stop()


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[Cluster]:
    """A scheduler without workers (the test adds them); stopped at teardown."""
    with started(tmp_path / "dask") as c:
        yield c


@pytest.fixture(scope="module")
def mpc_local(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """The MPC campaign's spec and its result on the local engine (the reference)."""
    folder = tmp_path_factory.mktemp("mpc")
    spec = mpc_spec(folder)
    local = run_campaign(spec, folder / "local", workers=2)
    assert local.status == "ok" and len(local.table) == 10
    return spec, local


def assert_same_runs(local: Any, remote: Any) -> None:
    """Every run ok on both, the same KPIs (to 1e-12) and the same results.csv."""
    assert remote.status == "ok", remote.table[["run", "variant", "status", "reason"]]
    a = local.table.sort_values(["run", "variant"]).reset_index(drop=True)
    b = remote.table.sort_values(["run", "variant"]).reset_index(drop=True)
    assert list(a["status"]) == list(b["status"]) == ["ok"] * len(a)
    compared = [c for c in a.columns if c not in NOT_COMPARED]
    for column in compared:
        if pd.api.types.is_numeric_dtype(a[column]):
            np.testing.assert_allclose(b[column].to_numpy(float), a[column].to_numpy(float),
                                       rtol=1e-12, atol=1e-12, err_msg=column)
        else:
            assert list(b[column]) == list(a[column]), column
    for folder in sorted((local.out / "runs").iterdir()):
        other = remote.out / "runs" / folder.name
        assert (other / "results.csv").read_bytes() == (folder / "results.csv").read_bytes(), \
            folder.name


def overlapping_runs(records: list[dict]) -> int:
    """Pairs of runs that computed at the same time in the same worker process, on two of
    its threads (Dask's task stream)."""
    spans = []
    for r in records:
        if not str(r.get("key", "")).startswith("cosim-") or "assets" in str(r["key"]):
            continue
        for ss in r.get("startstops", ()):
            if ss.get("action") == "compute":
                spans.append((r["worker"], r.get("thread"), ss["start"], ss["stop"]))
    return sum(1 for i, (w, th, s, e) in enumerate(spans) for (w2, th2, s2, e2) in spans[i + 1:]
               if w == w2 and th != th2 and s < e2 and s2 < e)


def test_one_worker_with_two_threads(cluster: Cluster, mpc_local: tuple[Path, Any],
                                     tmp_path: Path) -> None:
    from distributed import Client, get_task_stream

    spec, local = mpc_local
    cluster.add_worker(nworkers=1, nthreads=2)
    assert list(cluster.wait_for_workers(1).values()) == [2]
    with Client(cluster.address, timeout="30s") as client, \
            get_task_stream(client=client) as stream:
        remote = run_campaign(spec, tmp_path / "remote", scheduler=cluster.address)
    assert_same_runs(local, remote)
    # the shape was exercised: runs did share the worker process at the same time
    assert overlapping_runs(stream.data) > 0
    assert remote.summary["workers"] == cluster.address


def test_two_single_thread_workers(cluster: Cluster, mpc_local: tuple[Path, Any],
                                   tmp_path: Path) -> None:
    spec, local = mpc_local
    cluster.add_worker(nworkers=2, nthreads=1)
    assert sorted(cluster.wait_for_workers(2).values()) == [1, 1]
    remote = run_campaign(spec, tmp_path / "remote", scheduler=cluster.address)
    assert_same_runs(local, remote)


def start_campaign(spec: Path, out: Path, address: str) -> tuple[threading.Thread, dict]:
    """``run_campaign`` on ``address`` in a thread; its result (or error) lands in a dict."""
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["result"] = run_campaign(spec, out, scheduler=address)
        except BaseException as exc:  # handed to the test
            box["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    return thread, box


def finish(thread: threading.Thread, box: dict) -> Any:
    thread.join(timeout=WAIT)
    assert not thread.is_alive(), "the campaign did not finish"
    if "error" in box:
        raise box["error"]
    return box["result"]


def test_a_worker_that_joins_after_the_campaign_started(
        cluster: Cluster, mpc_local: tuple[Path, Any], tmp_path: Path) -> None:
    spec, local = mpc_local
    out = tmp_path / "remote"
    thread, box = start_campaign(spec, out, cluster.address)
    end = time.monotonic() + WAIT
    while not (out / "campaign.json").exists():   # connected, runs being submitted
        assert time.monotonic() < end and thread.is_alive(), box
        time.sleep(0.1)
    assert not list((out / "runs").glob("*/summary.json"))  # no worker, nothing ran yet
    cluster.add_worker(nworkers=1, nthreads=2)
    assert_same_runs(local, finish(thread, box))


def lost_worker_spec(folder: Path, plant: Path, scenario: str = "long.csv") -> Path:
    """``folder/slow.toml``: four PI runs on the stand-in ``plant`` (sensor bias and noise
    drawn), long enough to lose a worker in one."""
    return pi_campaign(folder, plant, {"sensor.h1.bias": {"uniform": [-0.01, 0.01]},
                                       "sensor.h2.noise": {"uniform": [0.0, 0.002]}},
                       file="slow.toml", scenario=scenario, name="lost-worker", runs=4, seed=2)


def _executing(dask_worker: Any) -> tuple[int, list[str]]:
    """On a worker: its process id and the runs it is executing."""
    keys = [str(ts.key) for ts in dask_worker.state.executing]
    return os.getpid(), [k for k in keys if k.startswith("cosim-") and "assets" not in k]


def executing_run(client: Any) -> tuple[str, int]:
    """A run's task key being executed (not only assigned) that has announced its start on
    the scheduler (a run killed before that is not charged a try: on a loaded machine the
    gap is long enough to hit), and its worker's process id."""
    from cosim.campaign.task import START_TOPIC

    end = time.monotonic() + WAIT
    while time.monotonic() < end:
        started = {str(m.get("key")) for _, m in client.get_events(START_TOPIC)
                   if isinstance(m, dict)}
        for pid, keys in client.run(_executing).values():
            for key in keys:
                if key in started:
                    return key, pid
        time.sleep(0.05)
    raise AssertionError("no run was executed")


@pytest.mark.parametrize("allowed_failures", [0, None],
                         ids=["allowed-failures-0", "dask-default"])
def test_a_worker_killed_mid_run_costs_a_try_not_the_run(
        allowed_failures: int | None, tmp_path: Path, pyfmu_dir: Path) -> None:
    """SIGKILL to the worker process running a run (preemption, the OOM killer): the run
    is run again on a worker and the campaign ends ok with the local engine's KPIs."""
    from distributed import Client

    spec = lost_worker_spec(tmp_path, pyfmu_dir / "Slow.fmu")
    local = run_campaign(spec, tmp_path / "local", workers=2)
    env = ({} if allowed_failures is None else
           {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(allowed_failures)})
    with started(tmp_path / "dask", env) as cluster:
        cluster.add_worker(nworkers=2, nthreads=1)
        cluster.wait_for_workers(2)
        out = tmp_path / "remote"
        with Client(cluster.address, timeout="30s") as client:
            thread, box = start_campaign(spec, out, cluster.address)
            key, pid = executing_run(client)
            os.kill(pid, signal.SIGKILL)
            remote = finish(thread, box)
        assert_same_runs(local, remote)
        run = int(re.fullmatch(r"cosim-\w+-(\d+)-pi", key).group(1))  # type: ignore[union-attr]
        tries = dict(zip(remote.table["run"], remote.table["tries"], strict=True))
        retried = sum(t > 1 for t in tries.values())
        assert remote.summary["retried_runs"] == retried
        if allowed_failures == 0:
            # the engine counted the lost try; runs that were only waiting on that worker
            # (assigned, not started) were submitted again without using up a try
            assert tries[run] == 2 and retried == 1
        else:
            # the scheduler reran it within the engine's first try
            assert set(tries.values()) == {1}
        doc = json.loads((out / "runs" / f"{run:06d}-pi" / "summary.json").read_text())
        assert doc["campaign"]["tries"] == tries[run]


def test_a_run_that_kills_its_worker_every_time_fails_after_the_last_try(
        tmp_path: Path, pyfmu_dir: Path) -> None:
    spec = pyfmu_models.crashy_campaign(tmp_path, pyfmu_dir, runs=3, seed=3)
    with started(tmp_path / "dask",
                 {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"}) as cluster:
        cluster.add_worker(nworkers=2, nthreads=1)
        cluster.wait_for_workers(2)
        result = run_campaign(spec, tmp_path / "out", scheduler=cluster.address)
    table = result.table.sort_values("run")
    crashed = table["plant.crash_at"] == 300.0
    assert 0 < crashed.sum() < 3
    assert list(table["status"]) == ["failed" if c else "ok" for c in crashed]
    # the runs that waited on a crashing worker were not charged a try
    assert list(table["tries"]) == [MAX_TRIES if c else 1 for c in crashed]
    for reason in table[crashed]["reason"]:
        assert reason.startswith(f"the run killed its worker process in each of its "
                                 f"{MAX_TRIES} tries"), reason
    assert result.status == "failed"
    groups = result.summary["failures_by_reason"]
    assert len(groups) == 1 and next(iter(groups.values()))["count"] == crashed.sum()


def test_a_cluster_without_workers_stops_the_campaign_then_resume_runs_it(
        cluster: Cluster, tmp_path: Path, pyfmu_dir: Path) -> None:
    from cosim.campaign.cluster import NoWorkers

    spec = lost_worker_spec(tmp_path, pyfmu_dir / "Crashy.fmu", "short.csv")
    t0 = time.monotonic()
    result = run_campaign(spec, tmp_path / "out", scheduler=cluster.address,
                          worker_timeout=3.0)
    assert time.monotonic() - t0 < 60          # no hang: 3 s without a worker, then out
    assert isinstance(result.error, NoWorkers) and result.status == "interrupted"
    assert str(result.error) == ("no Dask worker for 3 s: 4 runs not run (start workers, then "
                                 "run the campaign again with --resume)")
    assert result.summary["runs"] == 0 and (tmp_path / "out" / "summary.json").exists()
    # the same through the command: one line, exit 1
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "campaign", str(spec), "--out",
                           str(tmp_path / "out2"), "--scheduler", cluster.address,
                           "--worker-timeout", "2", "--quiet"], capture_output=True,
                          text=True, timeout=WAIT, env=cluster.env)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].endswith(
        "no Dask worker for 2 s: 4 runs not run (start workers, then run the campaign again "
        "with --resume)"), proc.stderr
    assert "Traceback" not in proc.stderr
    # the workers come: --resume runs them
    cluster.add_worker(nworkers=1, nthreads=1)
    cluster.wait_for_workers(1)
    again = run_campaign(spec, tmp_path / "out", scheduler=cluster.address, resume=True)
    assert again.status == "ok" and again.summary["ok"] == 4


def test_worker_timeout_must_be_a_positive_number(tmp_path: Path) -> None:
    from cosim.core.errors import CosimError

    spec = mpc_spec(tmp_path)
    with pytest.raises(CosimError, match=r"--worker-timeout -1: expected a positive number"):
        run_campaign(spec, tmp_path / "out", worker_timeout=-1)
    assert not (tmp_path / "out").exists()
