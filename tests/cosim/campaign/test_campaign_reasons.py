"""Why a campaign run failed: the words ``cosim run`` uses for a run that cannot start, the
phase of an internal error with its traceback in the run folder, reasons grouped in
``summary.json``; and the worker's controller pool.

The runs go through the engine's own path without Dask: :func:`~cosim.campaign.engine.
prepare`, :func:`~cosim.campaign.task.run_task` (what a worker executes) and
:func:`~cosim.campaign.store.write_run` (what the client writes).
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.campaign import engine, store
from cosim.campaign.pool import ControllerPool, controller_key
from cosim.campaign.spec import load
from cosim.campaign.task import POOL, run_task
from cosim.core.errors import CosimError

SHORT = "time,ref.h1,ref.h2\n0,0.6,0.6\n500,0.7,\n1000,,\n"


def spec(tmp_path: Path, controller: str, tables: str = "", runs: int = 1,
         seed: int | None = None) -> Path:
    """A campaign of ``runs`` runs of :data:`SHORT` (seeded with ``seed`` when given) with
    ``controller``, ``tables`` after its ``[campaign]``, written in ``tmp_path``."""
    (tmp_path / "short.csv").write_text(SHORT)
    path = tmp_path / "spec.toml"
    seeded = f"seed = {seed}\n" if seed is not None else ""
    path.write_text(f'[campaign]\nruns = {runs}\n{seeded}scenario = "short.csv"\n'
                    f'controller = "{controller}"\n' + (f"\n{tables}" if tables else ""))
    return path


def run_in_process(spec_path: Path) -> tuple[object, dict]:
    """Every run of the spec, as the engine runs and writes it (no Dask): the runs table
    and the campaign's summary document."""
    tmp_path = spec_path.parent
    plan = engine.prepare(load(spec_path))
    out = tmp_path / "out"
    for task in store.open_folder(plan, out, resume=False, force=False):
        store.write_run(out, plan.spec, task, run_task(task, plan.assets), None)
    return store.build_report(plan.spec, out)


def run_dir(tmp_path: Path, run: int, variant: str) -> Path:
    return tmp_path / "out" / "runs" / f"{run:06d}-{variant}"


def test_an_unreachable_first_setpoint_is_named_as_cosim_run_names_it(tmp_path: Path) -> None:
    table, summary = run_in_process(spec(tmp_path, "robust-mpc", """\
[controller.options]
law = "paper"                   # the tracking law refuses no set-point

[setpoints]
count = 4
hold = 2500
h1 = [0.6, 1.4]
h2 = [0.6, 1.4]
""", runs=2, seed=4242))
    table = table.sort_values("run")
    assert list(table["status"]) == ["failed", "ok"]
    reason = table["reason"].iloc[0]
    # what cosim run says for the same first set-point
    doc = json.loads((run_dir(tmp_path, 0, "robust-mpc") / "summary.json").read_text())
    first = doc["campaign"]["setpoints"][0][1]
    assert first["h1"] == pytest.approx(0.658, abs=1e-3)
    assert first["h2"] == pytest.approx(1.307, abs=1e-3)
    scenario = tmp_path / "first.csv"
    scenario.write_text(f"time,ref.h1,ref.h2\n0,{first['h1']!r},{first['h2']!r}\n2500,,\n")
    with pytest.raises(CosimError) as cosim_run:
        cosim.run(scenario, controller="robust-mpc", options={"law": "paper"})
    assert reason == str(cosim_run.value)
    assert "is not reachable" in reason and "closest reachable equilibrium" in reason
    assert doc["steps"] == 0 and doc["campaign"]["tries"] == 1
    assert not (run_dir(tmp_path, 0, "robust-mpc") / store.TRACEBACK_FILE).exists()
    assert summary["failures_by_reason"][next(iter(summary["failures_by_reason"]))][
        "example"] == reason


def test_a_failed_certificate_hypothesis_is_named_as_cosim_run_names_it(
        tmp_path: Path) -> None:
    """A set-point that fails the theorem's hypotheses: with certificate = "require" the run is
    refused, in the campaign as by cosim.run, with the same reason; without it the run is
    uncertified and says why."""
    table, _ = run_in_process(spec(tmp_path, "robust-mpc", """\
[controller.options]
law = "paper"
certificate = "require"

[draw]
"ref.h1" = 0.4
"ref.h2" = 0.4
"""))
    scenario = tmp_path / "low.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.4,0.4\n1000,,\n")
    with pytest.raises(CosimError) as cosim_run:
        cosim.run(scenario, controller="robust-mpc",
                  options={"law": "paper", "certificate": "require"})
    assert table["status"].iloc[0] == "failed"
    assert table["reason"].iloc[0] == str(cosim_run.value)
    assert "recursive feasibility (eq:condition-recursive-feasibility) fails" in str(
        cosim_run.value)
    notices: list[str] = []
    out = cosim.run(scenario, controller="robust-mpc", options={"law": "paper"},
                    on_notice=notices.append)
    ctrl = out.summary["controller_summary"]
    assert out.status == "ok" and ctrl["certified"] is False
    assert ctrl["tightening"] == "measured"
    assert "recursive feasibility" in ctrl["certificate_reason"]
    assert len(notices) == 1 and notices[0].startswith("uncertified: set-point h1=0.4 m")


def test_a_bug_met_by_the_master_names_the_step_and_keeps_the_traceback(
        tmp_path: Path) -> None:
    table, summary = run_in_process(spec(tmp_path, "tests.cosim.sleepy:ForgetfulPI", """\
[controller.options]
forget_at = 500.0

[draw]
"sensor.h1.bias" = { uniform = [-0.01, 0.01] }
""", runs=2))
    assert list(table["status"]) == ["failed", "failed"]
    for run in (0, 1):
        reason = table["reason"].iloc[run]
        # the controller gave no outputs: met as the loop takes what it computed
        assert reason == "controller 'pi': step at t=500.0 failed: KeyError: 'qa'", reason
        folder = run_dir(tmp_path, run, "tests.cosim.sleepy:ForgetfulPI")
        trace = (folder / store.TRACEBACK_FILE).read_text()
        assert trace.startswith("Traceback (most recent call last):")
        assert "in _controller_step" in trace and "KeyError: 'qa'" in trace
        # the steps before the bug are kept
        assert json.loads((folder / "summary.json").read_text())["steps"] == 20
    # alike failures make one group
    groups = summary["failures_by_reason"]
    assert len(groups) == 1 and next(iter(groups.values()))["count"] == 2


def test_a_bug_in_the_controller_step_keeps_the_traceback(tmp_path: Path) -> None:
    table, _ = run_in_process(spec(tmp_path, "tests.cosim.sleepy:BuggyPI", """\
[controller.options]
fail_at = 250.0
"""))
    assert table["reason"].iloc[0] == ("controller 'pi': step at t=250.0 failed: IndexError: "
                                       "list index out of range")
    folder = run_dir(tmp_path, 0, "tests.cosim.sleepy:BuggyPI")
    trace = (folder / store.TRACEBACK_FILE).read_text()
    assert "sleepy.py" in trace and "IndexError: list index out of range" in trace


def test_a_bug_before_the_run_names_its_phase(tmp_path: Path) -> None:
    table, _ = run_in_process(spec(tmp_path, "tests.cosim.sleepy:ReadOnlyEstimatePI"))
    assert table["reason"].iloc[0] == ("building the controller: RuntimeError: "
                                       "initial_estimate is read-only")
    folder = run_dir(tmp_path, 0, "tests.cosim.sleepy:ReadOnlyEstimatePI")
    assert "RuntimeError: initial_estimate is read-only" in (
        folder / store.TRACEBACK_FILE).read_text()


def test_a_rerun_without_a_bug_removes_the_old_traceback(tmp_path: Path) -> None:
    plan = engine.prepare(load(spec(tmp_path, "pi")))
    out = tmp_path / "out"
    task = store.open_folder(plan, out, resume=False, force=False)[0]
    folder = out / "runs" / "000000-pi"
    folder.mkdir(parents=True)
    (folder / store.TRACEBACK_FILE).write_text("an older run's traceback")
    assert store.write_run(out, plan.spec, task, run_task(task, plan.assets), None) == "ok"
    assert not (folder / store.TRACEBACK_FILE).exists()


def test_a_run_takes_a_controller_of_its_own_and_gives_back_only_after_ok(
        tmp_path: Path) -> None:
    plan = engine.prepare(load(spec(tmp_path, "pi", """\
[[variant]]
name = "ok"

[[variant]]
name = "buggy"
controller = "tests.cosim.sleepy:BuggyPI"
options = { fail_at = 250.0 }
""")))
    ok_task, buggy_task = plan.tasks
    POOL.clear()
    first = run_task(ok_task, plan.assets)
    assert first["result"].status == "ok"
    assert POOL.idle() == 1
    again = run_task(ok_task, plan.assets)
    assert POOL.idle() == 1     # the same instance went out and came back
    np.testing.assert_array_equal(first["result"].rows, again["result"].rows)
    assert run_task(buggy_task, plan.assets)["result"].status == "failed"
    assert POOL.idle() == 1     # the failed run's controller was dropped


def test_the_pool_never_hands_one_instance_to_two_runs() -> None:
    pool = ControllerPool(size=3, factory=lambda name, options: object())
    held: list[object] = []
    lock = threading.Lock()
    start = threading.Barrier(4)

    def take() -> None:
        start.wait(timeout=30)
        _key, ctrl = pool.take("pi", {"a": 1})
        with lock:
            held.append(ctrl)

    threads = [threading.Thread(target=take) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert len(held) == 4 and len({id(c) for c in held}) == 4
    assert pool.built == 4
    for ctrl in held:
        pool.give_back(controller_key("pi", {"a": 1}), ctrl)
    assert pool.idle() == 3       # bounded: the oldest returned one was dropped
    key, ctrl = pool.take("pi", {"a": 1})
    assert ctrl is held[-1] and pool.built == 4
    pool.give_back(key, ctrl)
    other, _ = pool.take("pi", {"a": 2})
    assert other != key and pool.built == 5
