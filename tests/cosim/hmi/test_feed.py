"""What the page reads, from a real run without a browser: the robust MPC's declared plan
(in process and from its worker), the one-step prediction error the feed derives from it
(every step's plan read here; a page reads a few a second), and the operator's requests
answered between two steps, applied and audited."""

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
from cosim.hmi.actions import AUDIT_FILE, User
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
    from cosim.hmi.actions import Audit, operator_for

    path = tmp_path / "steps.csv"
    path.write_text(SCENARIO)
    sc = scenario.load(path)
    ctrl = registry.create("robust-mpc", {})
    if isolate:
        ctrl = IsolatedController(ctrl, "robust-mpc", {})
    opened = plants.open_plant(None, plants.PlantContext(sc, ctrl, ctrl.problem))
    master = Master(opened.component, ctrl, sc, io=opened.io, pacer=opened.pacer)
    feed = Recorder(Layout.of_run(master, {}), ctrl, plan_every=0.0)   # every step's plan
    feed.operator = operator_for(ctrl, master.refs, {"h1": (0.0, 2.0), "h2": (0.0, 2.0)},
                                 {"h1": "m", "h2": "m"},
                                 lambda o: feed.last(f"ref.{o}"))
    feed.audit = Audit(tmp_path / AUDIT_FILE)
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
    result, feed = _watched_run(tmp, False, [("ref.h1", 0.8), ("setting.R.qa", 0.0),
                                             ("ref.h2", 7.0)])
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
    result, feed, tmp = watched
    replies = [feed.replies[k] for k in sorted(feed.replies)]
    assert [r.accepted for r in replies] == [True, False, False]
    assert "positive definite" in replies[1].text and "outside [0, 2]" in replies[2].text
    with open(tmp / AUDIT_FILE, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["who"], r["what"], r["new"]) for r in rows] == [
        ("eng", "ref.h1", "0.8"), ("eng", "setting.R.qa", "0.0"), ("eng", "ref.h2", "7.0")]
    assert rows[0]["result"] == "accepted" and rows[1]["result"] == replies[1].text
    # the plant got it: ref.h1 is 0.8 from the sample the request was answered at, and the
    # level went there (the scenario's own 0.9 at t = 500 s came before it)
    t0 = float(rows[0]["time"])
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


def _scenario(tmp_path: Path) -> Path:
    path = tmp_path / "short.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,0.7,\n")
    return path
