"""Process-wide state a run touches, used from several threads at once (a campaign worker
started with ``--nthreads 2``): FMU loading (fmpy changes the working folder), the FMU log
routing, the signal guard, and whole runs of the same campaign side by side."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cosim.campaign import engine
from cosim.campaign.spec import load
from cosim.campaign.task import run_task
from cosim.core import fmu_log, interrupts
from cosim.core.fmu import FmuComponent
from tests.toml_text import campaign_spec

U = {"qa": 6.0e-4, "qb": 4.0e-4}


def side_by_side(fn: Callable[[int], object], n: int = 2) -> list[object]:
    """``fn(i)`` for i < n, each in a thread of its own, started together."""
    out: list[object] = [None] * n
    start = threading.Barrier(n)

    def target(i: int) -> None:
        start.wait(timeout=60)
        try:
            out[i] = fn(i)
        except BaseException as exc:  # handed to the test
            out[i] = exc

    threads = [threading.Thread(target=target, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert not any(t.is_alive() for t in threads)
    for value in out:
        if isinstance(value, BaseException):
            raise value
    return out


def simulate(path: Path, times: int) -> list[list[float]]:
    """``times`` short runs of the FMU (set up, 20 steps, terminated): the last outputs."""
    finals = []
    for _ in range(times):
        comp = FmuComponent(path)
        comp.setup(0.0)
        try:
            for k in range(20):
                comp.set_inputs(U)
                comp.step(25.0 * k, 25.0)
            finals.append(list(comp.get_outputs().values()))
        finally:
            comp.terminate()
    return finals


def test_fmus_loaded_by_two_threads_leave_the_working_folder_alone(fmu2_path: Path,
                                                                      tmp_path: Path) -> None:
    cwd = os.getcwd()
    expected = simulate(fmu2_path, 1)[0]
    results = side_by_side(lambda i: simulate(fmu2_path, 12))
    # each load changed into a binaries folder (removed at terminate) and back: the process
    # is still where it was, in a folder that exists
    assert os.getcwd() == cwd and Path(cwd).is_dir()
    for finals in results:
        assert finals == [expected] * 12


def test_the_fmi2_callbacks_are_built_once() -> None:
    got = side_by_side(lambda i: fmu_log.fmi2_callbacks(), 4)
    assert all(cb is got[0] for cb in got)


def test_a_worker_thread_never_sees_the_main_threads_signal_guard() -> None:
    with interrupts.handling_signals() as guard:
        assert guard is not None and interrupts.current() is guard

        def in_thread(i: int) -> tuple[object, object]:
            with interrupts.handling_signals() as inner:
                return inner, interrupts.current()

        assert side_by_side(in_thread) == [(None, None), (None, None)]
        with guard.deferred():   # the main thread's state is its own
            assert interrupts.current() is guard


def test_two_runs_side_by_side_give_the_numbers_of_one_after_the_other(
        tmp_path: Path) -> None:
    """A worker with two threads: two robust-MPC runs at once, each on a controller of its
    own, give what the same runs give one after the other."""
    (tmp_path / "short.csv").write_text("time,ref.h1,ref.h2\n0,0.6,0.6\n500,0.7,\n1000,,\n")
    spec = campaign_spec(tmp_path, runs=2, seed=9, scenario="short.csv",
                         controller="robust-mpc",
                         draw={"plant.gamma_a": {"uniform": [0.28, 0.32]},
                               "sensor.h1.bias": {"uniform": [-0.01, 0.01]}})
    plan = engine.prepare(load(spec))
    alone = [run_task(task, plan.assets)["result"] for task in plan.tasks]
    together = side_by_side(lambda i: run_task(plan.tasks[i], plan.assets)["result"])
    for a, b in zip(alone, together, strict=True):
        assert a.status == b.status == "ok", (a.reason, b.reason)  # type: ignore[attr-defined]
        np.testing.assert_array_equal(a.rows, b.rows)  # type: ignore[attr-defined]
    # and the two runs differ (different draws): the comparison could fail
    assert not np.array_equal(alone[0].rows, alone[1].rows)
