"""A campaign's [operator] events (cosim.campaign.operator_events): parsed with file:line
errors, drawn per run from their own seeded stream (an input out of service for a while, a
limit narrowed and given back), and run: each run's operator.csv holds its events."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from cosim.campaign import draws, spec
from cosim.cli import main
from cosim.core.errors import CosimError

SCENARIO = "time,ref.h1,ref.h2\n0,0.8,0.8\n1500,,\n"
SPEC = """\
[campaign]
name = "ops"
runs = 2
seed = 5
scenario = "{scenario}"
controller = "robust-mpc"

[operator]
count = 2
duration = [200.0, 400.0]
service = ["qb"]
"max.h1" = [1.1, 1.3]
"""


def _spec(tmp_path: Path, text: str = SPEC) -> Path:
    (tmp_path / "s.csv").write_text(SCENARIO)
    path = tmp_path / "ops.toml"
    path.write_text(text.format(scenario=tmp_path / "s.csv"))
    return path


def test_events_are_drawn_per_run_within_their_ranges(tmp_path: Path) -> None:
    s = spec.load(_spec(tmp_path))
    assert s.operator.kinds == ["op.service.qb", "op.max.h1"]
    ctx = draws.DrawContext.build(s, 0.0)
    runs = [draws.draw_run(s, i, ctx).operator for i in range(6)]
    assert runs == [draws.draw_run(s, i, ctx).operator for i in range(6)]   # seeded
    assert len({repr(r) for r in runs}) == 6
    for events in runs:
        assert all(150.0 <= t < 1500.0 for t, _ in events)   # after a tenth of the run
        for _, change in events:
            (name, value), = change.items()
            assert (name, value) in {("op.service.qb", 0.0), ("op.service.qb", 1.0),
                                     ("op.max.h1", 2.0)} or (name == "op.max.h1"
                                                             and 1.1 <= value <= 1.3)


@pytest.mark.parametrize(("table", "message"), [
    ("count = 1\nservice = [\"qa\"]\n", "[operator] duration = None: expected [low, high]"),
    ("duration = [1.0, 2.0]\n", "[operator]: no events"),
    ("duration = [1.0, 2.0]\n\"max.h1\" = [2.0, 1.0]\n", "[operator] max.h1 = [2.0, 1.0]"),
    ("duration = [1.0, 2.0]\nlimit = 3\n", "[operator] limit: expected count, duration"),
])
def test_bad_operator_tables_name_the_line(tmp_path: Path, table: str, message: str) -> None:
    path = _spec(tmp_path, SPEC.split("[operator]")[0] + "[operator]\n" + table)
    with pytest.raises(CosimError) as err:
        spec.load(path)
    assert str(err.value).startswith(f"{path}:") and message in str(err.value), str(err.value)


@pytest.mark.slow
def test_a_campaign_runs_its_operator_events(tmp_path: Path) -> None:
    path = _spec(tmp_path)
    assert main(["campaign", str(path), "--out", str(tmp_path / "out"), "--workers", "1",
                 "--quiet"]) == 0
    s = spec.load(path)
    ctx = draws.DrawContext.build(s, 0.0)
    for run in range(2):
        (audit,) = (tmp_path / "out" / "runs").glob(f"{run:06d}-*/operator.csv")
        rows = list(csv.DictReader(audit.open()))
        drawn = [(t, name) for t, change in draws.draw_run(s, run, ctx).operator
                 for name in change]
        assert [r["what"] for r in rows] == [name for _, name in drawn]
        for r, (t, _) in zip(rows, drawn, strict=True):   # at the first sample from then
            assert t <= float(r["time"]) < t + 25.0
        assert {r["who"] for r in rows} == {"scenario"}
