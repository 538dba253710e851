"""A server in a worker process (:mod:`cosim.core.worker`): calls answered, a hung call
killed at its timeout, a death named with the worker's last output, a flood of output
drained and dropped, errors by kind, the worker in a process group of its own, started from
a script that has no main guard."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.core.errors import CosimError, SimulationFailed
from cosim.core.worker import OUTPUT_TAIL, Worker

SERVER = "tests.cosim.core.worker_servers:Echo"
ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def worker() -> Worker:
    w = Worker("echo", SERVER, {"greeting": "hi"}, timeout=30.0)
    w.start()
    yield w
    w.stop()


def test_a_call_is_answered_by_the_server_in_its_own_process_group(worker: Worker) -> None:
    assert worker.call("echoing", "echo", [1.5, "a"]) == ("hi", [1.5, "a"])
    assert os.getpgid(worker.pid) == worker.pid != os.getpgid(0)
    pid = worker.pid
    worker.stop()
    assert not worker.alive and worker.pid is None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_a_hung_call_is_killed_at_the_timeout(worker: Worker) -> None:
    worker.timeout = 0.5
    with pytest.raises(SimulationFailed, match=r"^echo: sleeping took longer than the step "
                                               r"timeout of 0\.5 s \(worker killed\)$"):
        worker.call("sleeping", "sleep", 60.0)
    assert not worker.alive
    with pytest.raises(SimulationFailed, match="echoing failed: no worker"):
        worker.call("echoing", "echo", 1)


@pytest.mark.parametrize(("method", "args", "why"), [
    ("exit", (3,), "worker died (exit code 3)"),
    ("exit", (0,), "worker died (exit code 0)"),
    ("last_words", ("model.c:12: giving \x1b[31mup\n",),
     r"worker died (signal 6, SIGABRT); it last printed: 'model.c:12: giving \\x1b[31mup'")])
def test_a_death_is_named_with_the_last_output(worker: Worker, method: str, args: tuple,
                                               why: str) -> None:
    with pytest.raises(SimulationFailed) as info:
        worker.call("stepping", method, *args)
    assert str(info.value) == f"echo: stepping failed: {why}"
    assert not worker.alive


def test_a_flood_of_output_is_drained_and_dropped(worker: Worker) -> None:
    assert worker.call("flooding", "flood", 8) == worker.pid
    assert worker.call("echoing", "echo", 2) == ("hi", 2)   # it is never blocked on a pipe
    assert worker.output_bytes() == 8 * 1024 * 1024
    assert len(worker._tail._data) <= OUTPUT_TAIL


def test_errors_keep_their_kind(worker: Worker) -> None:
    with pytest.raises(CosimError, match="that value is bad input") as info:
        worker.call("refusing", "refuse")
    assert not isinstance(info.value, SimulationFailed)
    with pytest.raises(SimulationFailed, match=r"^ValueError: an internal error$"):
        worker.call("failing", "fail")
    with pytest.raises(SimulationFailed, match="unknown request '_private'"):
        worker.call("peeking", "_private")
    assert worker.call("echoing", "echo", 3) == ("hi", 3)   # the worker lives on


def test_a_server_that_cannot_be_built_answers_every_call_with_why() -> None:
    w = Worker("echo", SERVER, {"refuse": True}, timeout=30.0)
    w.start()
    try:
        for _ in range(2):
            with pytest.raises(CosimError, match="refused to start"):
                w.call("echoing", "echo", 1)
    finally:
        w.stop()


def test_a_script_without_a_main_guard_starts_a_worker(tmp_path: Path) -> None:
    """The worker is a fresh interpreter: a user's script that starts one at its top level
    (no ``if __name__ == "__main__":``) is not run again in it, as ``multiprocessing``'s
    spawn would."""
    script = tmp_path / "script.py"
    script.write_text(f"""
from cosim.core.worker import Worker
print("script ran")
w = Worker("echo", {SERVER!r}, {{"greeting": "hi"}}, timeout=30.0)
w.start()
print(w.call("echoing", "echo", 7))
w.stop()
""")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, check=False, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "script ran\n('hi', 7)\n"


def test_arguments_that_cannot_travel_are_named() -> None:
    w = Worker("echo", SERVER, {"greeting": lambda: "hi"}, timeout=30.0)
    with pytest.raises(CosimError, match=r"^echo: its arguments cannot be sent to its worker "
                                         r"process: "):
        w.start()
    assert not w.alive
