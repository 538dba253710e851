"""What the page reads, from a real run without a browser: the robust MPC's declared plan
(in process and from its worker), the one-step prediction error the feed derives from it
(every step's plan read here; a page reads a few a second), and the operator's requests
answered between two steps by the run's operator desk, applied and audited in the one
operator.csv the scenario's op.* cells are rows of too."""

from __future__ import annotations

import csv
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.core.component import Capability, Prediction
from cosim.core.errors import CosimError
from cosim.core.operator import AUDIT_COLUMNS, AUDIT_FILE
from cosim.hmi.actions import User
from cosim.hmi.feed import Feed, Layout

SCENARIO = "time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n1000,,1.0\n2500,,\n"


class Recorder(Feed):
    """The feed of a run, and every plan it was given (a test's view of the watcher)."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.plans: list[tuple[float, Prediction]] = []

    def _plan(self, row: list[float]) -> None:
        super()._plan(row)
        if self.prediction is not None and (not self.plans
                                            or self.plans[-1][1] is not self.prediction[1]):
            self.plans.append(self.prediction)


def _watched_run(tmp_path: Path, isolate: bool, requests: list[tuple[str, float]]
                 ) -> tuple[object, Recorder]:
    """A real closed-loop run whose master is watched by a :class:`Recorder`; each of
    ``requests`` is made from another thread once the run has 30 rows (after the scenario's
    last step of h1), as a page would."""
    from cosim.core import plants, registry, scenario
    from cosim.core.isolated import IsolatedController
    from cosim.core.master import Master
    from cosim.hmi.actions import operator_for

    path = tmp_path / "steps.csv"
    path.write_text(SCENARIO)
    sc = scenario.load(path)
    ctrl = registry.create("robust-mpc", {})
    if isolate:
        ctrl = IsolatedController(ctrl, "robust-mpc", {})
    opened = plants.open_plant(None, plants.PlantContext(sc, ctrl, ctrl.problem))
    master = Master(opened.component, ctrl, sc, io=opened.io, pacer=opened.pacer)
    feed = Recorder(Layout.of_run(master, {}), ctrl, operator_for(master),
                    plan_every=0.0)   # every step's plan
    user = User("eng", "engineer")

    def ask() -> None:
        while len(feed.rows) < 30 and feed.status == "running":
            time.sleep(0.005)
        for action, value in requests:
            feed.request(action, value, user)

    asker = threading.Thread(target=ask)
    asker.start()
    result = master.run(watch=feed)
    feed.finish(result.status, result.reason)
    asker.join()
    return result, feed


@pytest.fixture(scope="module")
def watched(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, Recorder, Path]:
    tmp = tmp_path_factory.mktemp("watched")
    result, feed = _watched_run(tmp, False, [("ref.h1", 0.8), ("R.qa", 0.0), ("ref.h2", 7.0)])
    return result, feed, tmp


def test_the_plan_is_the_robust_mpcs_in_the_problems_units(watched: tuple) -> None:
    result, feed, _ = watched
    assert result.status == "ok", result.reason
    assert Capability.PREDICTION in feed.ctrl.capabilities
    t, plan = feed.prediction
    n = feed.ctrl.mpc.fhocp.N
    assert t == result.rows[-1][0] and plan.step == 25.0 and not plan.fallback
    for o in ("h1", "h2"):
        assert len(plan.outputs[o]) == n + 1 and len(plan.low[o]) == len(plan.high[o]) == n
        # the tightened box lies inside the engineer's, and the plan keeps it
        assert all(0.0 < lo < hi < 2.0 for lo, hi in zip(plan.low[o], plan.high[o],
                                                          strict=True))
        assert all(lo - 1e-6 <= y <= hi + 1e-6 for y, lo, hi in zip(
            plan.outputs[o][1:n], plan.low[o][1:], plan.high[o][1:], strict=True))
    for u, (lo, hi) in (("qa", (0.0, 9.05e-4)), ("qb", (0.0, 1.11e-3))):
        assert len(plan.inputs[u]) == n and all(lo <= v <= hi for v in plan.inputs[u])
    # the plan's first input is the one applied at that step
    assert plan.inputs["qa"][0] == pytest.approx(result.rows[-1][result.columns.index(
        "ctrl.qa")], rel=1e-9)


def test_the_prediction_error_is_the_measurement_against_the_last_plan(watched: tuple) -> None:
    result, feed, _ = watched
    times = {row[0]: row for row in result.rows}
    j = result.columns.index("plant.h1")
    assert len(feed.errors) == len(result.rows) - 1
    plans = dict(feed.plans)
    for t, errors in feed.errors:
        before = plans[t - 25.0]
        assert errors["h1"] == times[t][j] - before.outputs["h1"][1]
    worst = max(abs(e["h1"]) for _, e in feed.errors)
    assert 0 < worst < 0.05   # the model predicts the plant to within a few cm a sample ahead


def test_requests_are_answered_between_steps_applied_and_audited(watched: tuple) -> None:
    result, feed, _ = watched
    replies = [feed.replies[k] for k in sorted(feed.replies)]
    assert [r.accepted for r in replies] == [True, False, False]
    assert "positive definite" in replies[1].text and "outside [0, 2]" in replies[2].text
    rows = result.operator_rows   # the desk's audit: operator.csv's rows
    assert feed.audit is feed.operator.desk.rows and list(feed.audit) == rows
    assert [(who, what, new) for _, who, what, _, new, _ in rows] == [
        ("eng", "ref.h1", 0.8), ("eng", "R.qa", 0.0), ("eng", "ref.h2", 7.0)]
    assert rows[0][5] == "accepted" and rows[1][5] == f"refused: {replies[1].text}"
    # the plant got it: ref.h1 is 0.8 from the sample the request was answered at, and the
    # level went there (the scenario's own 0.9 at t = 500 s came before it)
    t0 = rows[0][0]
    ref, h1 = (result.columns.index(c) for c in ("ref.h1", "plant.h1"))
    after = [row for row in result.rows if row[0] >= t0]
    assert t0 > 0 and all(row[ref] == 0.8 for row in after)
    assert all(row[ref] != 0.8 for row in result.rows if row[0] < t0)
    assert abs(result.rows[-1][h1] - 0.8) < 0.01
    assert feed.ctrl.settings()["R.qa"].start > 0   # refused: unchanged


def test_an_isolated_controller_hands_its_plan_from_its_worker(tmp_path: Path) -> None:
    result, feed = _watched_run(tmp_path, True, [])
    assert result.status == "ok", result.reason
    t, plan = feed.prediction
    assert len(plan.outputs["h1"]) == 81 and t == result.rows[-1][0]
    assert len(feed.errors) == len(result.rows) - 1
    assert np.isfinite([e["h2"] for _, e in feed.errors]).all()


def test_a_port_in_use_is_refused_before_the_run(tmp_path: Path) -> None:
    import socket


    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(CosimError, match=rf"--hmi 127.0.0.1:{port}: cannot listen"):
            cosim.run(_scenario(tmp_path), out=tmp_path / "out", hmi=f"{port}", figure=False)
    assert not (tmp_path / "out").exists()


def test_the_api_serves_the_page_and_stops_it(tmp_path: Path) -> None:
    import urllib.request

    from cosim.live.process import free_port

    port, seen = free_port(), []

    def notice(text: str) -> None:
        seen.append(text)

    def fetch(_k: int) -> None:
        if len(seen) == 1:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as r:
                seen.append(r.read().decode())

    out = cosim.run(_scenario(tmp_path), out=tmp_path / "out", hmi=str(port), figure=False,
                    on_notice=notice, on_step=fetch)
    assert out.status == "ok" and seen[0] == f"the run's page: http://127.0.0.1:{port}/"
    page = seen[1]
    assert "bokeh" in page and "cdn." not in page and "https://" not in page
    assert not (tmp_path / "out" / AUDIT_FILE).exists()   # no request, no audit
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2)


def test_the_pages_operator_acts_through_the_desk_into_one_operator_csv(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The page's requests (an operator's op.* limit and set-point, an engineer's setting
    the operator may not change) and the scenario's op.* cell are rows of one operator.csv
    with the desk's columns, written once with the run's files."""
    from cosim.hmi import serving
    from cosim.live.process import free_port

    feeds: list[Feed] = []

    class Kept(Feed):
        def __init__(self, *args: object, **kw: object) -> None:
            super().__init__(*args, **kw)  # type: ignore[arg-type]
            feeds.append(self)

    def ask(k: int) -> None:   # the loop's thread, before its turn to the watcher
        if k == 3:
            ops = User("ops", "operator")
            for action, value in (("op.max.qa", 6e-4), ("ref.h2", 0.7), ("R.qa", 1.0)):
                feeds[0].request(action, value, ops)

    monkeypatch.setattr(serving, "Feed", Kept)
    path = tmp_path / "ops.csv"
    path.write_text("time,ref.h1,ref.h2,op.mode\n0,0.65,0.65,auto\n250,,,\n")
    out = cosim.run(path, out=tmp_path / "out", hmi=str(free_port()), figure=False,
                    on_step=ask, on_notice=lambda _text: None)
    assert out.status == "ok", out.summary.get("reason")
    feed = feeds[0]
    actions = {a.name: a for a in feed.actions}
    assert {"op.mode", "op.max.qa", "op.service.qb", "ref.h1", "R.qa"} <= set(actions)
    assert actions["op.max.qa"].value == 6e-4 and actions["op.mode"].choices == ("0", "1")
    assert actions["R.qa"].role == "engineer" and actions["op.max.qa"].role == "operator"
    with open(tmp_path / "out" / AUDIT_FILE, newline="") as fh:
        reader = csv.reader(fh)
        assert tuple(next(reader)) == AUDIT_COLUMNS
        rows = list(reader)
    assert [(who, what, new, result.split(":")[0]) for _, who, what, _, new, result in rows] == [
        ("scenario", "op.mode", "1.0", "accepted"), ("ops", "op.max.qa", "0.0006", "accepted"),
        ("ops", "ref.h2", "0.7", "accepted"), ("ops", "R.qa", "1.0", "refused")]
    assert "engineer's to change" in rows[3][5]
    t0 = float(rows[1][0])
    df = out.to_pandas()
    assert (df.loc[df.time >= t0, "ref.h2"] == 0.7).all()
    assert (df.loc[df.time < t0, "ref.h2"] == 0.65).all()
    assert out.summary["controller_summary"]["operator"]["final"]["limits"]["qa"][1] == 6e-4


def _scenario(tmp_path: Path) -> Path:
    path = tmp_path / "short.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,0.7,\n")
    return path
