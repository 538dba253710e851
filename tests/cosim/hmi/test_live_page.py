"""The run's page in a real browser during a real run: ``cosim run --hmi`` against ``cosim
serve-plant`` (a live rehearsal on 127.0.0.1), read by headless Chromium; then ``cosim view``
of the same run's folder.

One run and one browser for the module: the page shows what the run records (each panel's
last value against ``results.csv``, the mode, the prediction's length against the MPC's
horizon), pushes its updates without a reload and loads nothing from outside; an engineer
logs in, moves a set-point (the plant goes there) and asks for a setting the controller
refuses (the reason shown); both are rows of ``operator.csv``. The run is long (40,000 s of
plant time) and the test stops it with Ctrl-C once the plant got there, as an operator
would: a loaded machine may draw the page slowly, and the run waits for it. The replay
shows the last sample and the operator's rows, and its slider goes back to the first.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest

from cosim.core.csvio import read_table
from cosim.live.process import free_port, start_served_plant
from tests.cosim.hmi.browser import (
    DOCS_SCREENSHOT,
    badges,
    browser,
    cosim,
    env,
    readouts,
    start,
    stop,
    wait_for_line,
    wait_until,
)

pytestmark = pytest.mark.slow

SPEED = 200.0   # Ts = 25 s: a sample every 0.125 s (the run 200 s long unless stopped)
SCENARIO = "time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n1000,,1.0\n40000,,\n"
PASSWORD = "commissioning-2024"
#: Seconds a step of the browser may take: a machine under load draws the page slowly.
WAIT = 120


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """The run (its page's address and folder), the browser's page, and what the tests
    saw; everything stopped at the end."""
    tmp = tmp_path_factory.mktemp("hmi")
    (tmp / "steps.csv").write_text(SCENARIO)
    made = subprocess.run([sys.executable, "-m", "cosim.hmi.users", "users.toml", "eng",
                           "engineer"], cwd=tmp, env=env(COSIM_HMI_PASSWORD=PASSWORD),
                          capture_output=True, text=True, timeout=60, check=False)
    assert made.returncode == 0, made.stderr
    assert PASSWORD not in (tmp / "users.toml").read_text()
    plant = start_served_plant("--security", "None", "--speed", str(SPEED), "--frozen",
                               log=tmp / "plant.log", env=env())
    port = free_port()
    run = start(cosim("run", "steps.csv", "--plant", plant.endpoint, "--speed", str(SPEED),
                      "--security", "None", "--out", "run", "--no-figure", "--hmi", str(port),
                      "--hmi-users", "users.toml"), tmp / "run.log", cwd=tmp)
    try:
        line = wait_for_line(run, tmp / "run.log", "cosim run: the run's page: ", 120)
        with browser() as b:
            page = b.new_page(viewport={"width": 1280, "height": 1500})
            page.set_default_timeout(WAIT * 1000)
            yield {"tmp": tmp, "url": line.rsplit(" ", 1)[1], "run": run, "page": page,
                   "browser": b, "seen": []}
    finally:
        stop(run, 60)
        plant.stop()


def test_the_page_follows_the_run_as_it_goes(live: dict[str, Any]) -> None:
    page, url = live["page"], live["url"]
    assert url.startswith("http://127.0.0.1:") and url.endswith("/")
    page.goto(url)
    first = wait_until(lambda: readouts(page).get("h1"), WAIT)
    later = wait_until(lambda: (r := readouts(page)) and float(r["h1"]["t"]) > float(
        first["t"]) and r, WAIT)   # pushed: the same page, no reload
    live["seen"].append(later)
    assert set(later) == {"h1", "h2", "qa", "qb"}
    assert later["h1"]["horizon"] == later["h2"]["horizon"] == "81"   # N + 1 samples
    status = badges(page)
    assert status["mode"] == "auto" and status["certificate"] == "certified"
    assert status["run"].startswith("running") and status["fresh"] in ("fresh", "stale")
    assert status["solver"].startswith("optimal")
    sources = page.evaluate("() => Array.from(document.querySelectorAll("
                            "'script[src], link[href]')).map(e => e.src || e.href)")
    assert sources and all(s.startswith(url) for s in sources), sources   # nothing from a CDN


def test_an_engineer_moves_a_set_point_and_a_refused_setting_says_why(
        live: dict[str, Any]) -> None:
    page, url = live["page"], live["url"]
    switch = page.locator(".hmi-switch-ref-h1 input")
    assert switch.is_disabled()   # nobody logged in: viewing only
    page.goto(f"{url}login?next=/")
    page.fill("input[name=name]", "eng")
    page.fill("input[name=password]", PASSWORD)
    page.click("button[type=submit]")
    wait_until(lambda: "eng (engineer)" in page.inner_text(".hmi-user"), WAIT)
    # after the scenario's last move of h1 (t = 500 s): the request is the last word
    wait_until(lambda: float(readouts(page)["h1"]["t"]) >= 1100.0, WAIT)
    switch.fill("0.8")
    page.click(".hmi-apply-ref-h1 button")
    page.wait_for_selector(".hmi-reply [data-state=accepted]", timeout=WAIT * 1000)
    page.locator(".hmi-switch-R-qa input").fill("0")
    page.click(".hmi-apply-R-qa button")
    refused = page.wait_for_selector(".hmi-reply [data-state=refused]", timeout=WAIT * 1000)
    assert "positive definite" in refused.inner_text()
    # the plant goes there: then the run is stopped (Ctrl-C), its rows kept
    wait_until(lambda: abs(float(readouts(page)["h1"]["value"]) - 0.8) < 0.01, WAIT, 0.5)
    live["seen"].append(readouts(page))
    shot = live["tmp"] / "hmi_live.png"
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 50_000
    if os.environ.get("COSIM_SCREENSHOT") == "1":   # the docs' picture, on demand
        shutil.copyfile(shot, DOCS_SCREENSHOT)
    assert stop(live["run"], 60) == 130


def test_what_the_page_showed_is_what_the_run_recorded(live: dict[str, Any]) -> None:
    tmp = live["tmp"]
    assert "interrupted (SIGINT)" in (tmp / "run.log").read_text()
    summary = json.loads((tmp / "run" / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["controller_summary"]["N"] == 80
    table = read_table(tmp / "run" / "results.csv")
    times = list(table.time)
    for seen in live["seen"]:
        for signal, shown in seen.items():
            column = f"plant.{signal}" if signal in ("h1", "h2") else f"ctrl.{signal}"
            i = times.index(float(shown["t"]))
            assert float(shown["value"]) == table.column(column)[i], (signal, shown)
    with open(tmp / "run" / "operator.csv", newline="") as fh:
        audit = list(csv.DictReader(fh))
    assert [(r["who"], r["what"], float(r["new"]), r["result"] == "accepted")
            for r in audit] == [("eng", "ref.h1", 0.8, True), ("eng", "R.qa", 0.0, False)]
    assert "positive definite" in audit[1]["result"]
    t0 = float(audit[0]["time"])
    ref, h1 = table.column("ref.h1"), table.column("plant.h1")
    assert all((ref[i] == 0.8) == (t >= t0) for i, t in enumerate(times) if t >= 1000.0)
    assert abs(h1[-1] - 0.8) < 0.01   # the plant got it


def test_the_finished_run_replays_with_a_time_slider(live: dict[str, Any]) -> None:
    tmp, page = live["tmp"], live["browser"].new_page(viewport={"width": 1280, "height": 1200})
    page.set_default_timeout(WAIT * 1000)
    port = free_port()
    view = start(cosim("view", "run", "--hmi", str(port), "--duration", "600"),
                 tmp / "view.log", cwd=tmp)
    try:
        wait_for_line(view, tmp / "view.log", "cosim view: run: http://", 60)
        page.goto(f"http://127.0.0.1:{port}/")
        shown = wait_until(lambda: readouts(page).get("h1"), WAIT)
        table = read_table(tmp / "run" / "results.csv")
        assert float(shown["t"]) == table.time[-1]
        assert float(shown["value"]) == table.column("plant.h1")[-1]
        log = page.locator(".hmi-audit-row").all_inner_texts()
        assert len(log) == 2 and "ref.h1 " in log[0] and "positive definite" in log[1]
        page.locator(".hmi-slider .noUi-handle").focus()
        page.keyboard.press("Home")
        wait_until(lambda: float(readouts(page)["h1"]["t"]) == table.time[0], WAIT)
        assert badges(page)["run"].startswith("ended interrupted · t = 0 of")
    finally:
        time.sleep(0.2)
        code = stop(view)
    assert code == 0 and "stopped (SIGINT)" in (tmp / "view.log").read_text()
