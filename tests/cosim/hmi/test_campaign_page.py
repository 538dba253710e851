"""A campaign's page in a real browser: ``cosim campaign --hmi`` serves it while the
campaign runs, and ``cosim view`` of the finished campaign lists its runs with their KPIs
(as each run's ``summary.json`` has them), each linked to its own page."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from cosim.core.csvio import read_table
from cosim.live.process import free_port
from tests.cosim.commands.test_cli_campaign import SPEC  # two runs of the PI, a bias drawn
from tests.cosim.hmi.browser import (
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



def test_the_campaigns_runs_with_their_kpis_and_pages(tmp_path: Path) -> None:
    (tmp_path / "short.csv").write_text("time,ref.h1,ref.h2\n0,0.6,0.6\n500,0.7,\n1000,,\n")
    (tmp_path / "spec.toml").write_text(SPEC)
    port = free_port()
    proc = subprocess.run(cosim("campaign", "spec.toml", "--out", "out", "--workers", "1",
                                "--quiet", "--hmi", str(port)), cwd=tmp_path, env=env(),
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    assert f"cosim campaign: the campaign's page: http://127.0.0.1:{port}/" in proc.stderr
    runs = sorted(p.name for p in (tmp_path / "out" / "runs").iterdir())
    assert len(runs) == 2
    view = start(cosim("view", "out", "--hmi", str(port := free_port())), tmp_path / "v.log",
                 cwd=tmp_path)
    try:
        wait_for_line(view, tmp_path / "v.log", "cosim view: out: http://", 60)
        with browser() as b:
            page = b.new_page()
            page.set_default_timeout(120_000)
            page.goto(f"http://127.0.0.1:{port}/")
            rows = wait_until(lambda: page.locator(".hmi-run").evaluate_all(
                "els => els.map(e => [e.dataset.run, ...Array.from(e.cells).map("
                "c => c.innerText)])"), 120)
            assert [r[0] for r in rows] == runs
            for name, _link, status, violations, iae_h1, iae_h2, _reason in rows:
                doc = json.loads((tmp_path / "out" / "runs" / name / "summary.json")
                                 .read_text())
                assert status == doc["status"] == "ok"
                assert int(violations) == sum(v["count"] for v in
                                              doc["kpis"]["violations"].values())
                assert float(iae_h1) == pytest.approx(doc["kpis"]["iae"]["h1"], rel=1e-3)
                assert float(iae_h2) == pytest.approx(doc["kpis"]["iae"]["h2"], rel=1e-3)
            page.click(f".hmi-run[data-run='{runs[1]}'] a")
            shown = wait_until(lambda: readouts(page).get("qa"), 120)
            table = read_table(tmp_path / "out" / "runs" / runs[1] / "results.csv")
            assert float(shown["t"]) == table.time[-1]
            assert float(shown["value"]) == table.column("ctrl.qa")[-1]
    finally:
        assert stop(view) == 0
