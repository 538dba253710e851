"""KPIs on hand-made rows, and the results.csv / summary.json formats."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from cosim.core import kpis
from cosim.core.master import RunResult
from cosim.core.results import write, write_csv

COLUMNS = ["time", "ref.h1", "plant.h1", "ctrl.qa", "ctrl.cost"]
ROWS = [
    [0.0, 1.0, 0.5, 1.0, 3.0],
    [10.0, 1.0, 0.8, 3.0, math.nan],
    [20.0, 2.0, 2.5, -1.0, 1.0],
    [30.0, 2.0, 2.0, 0.0, 0.1 + 0.2],
]


def test_kpis_by_hand() -> None:
    k = kpis.compute(COLUMNS, ROWS, ["h1"], ["h1"], ["qa"], {"h1": (0.0, 2.0), "qa": (0.0, 2.0)})
    # |ref - y| held over each 10 s interval: 0.5, 0.2, 0.5 (the last row closes the run)
    assert k["iae"]["h1"] == pytest.approx(10 * (0.5 + 0.2 + 0.5))
    assert k["final_error"]["h1"] == 0.0
    assert k["violations"]["h1"] == {"max": 0.5, "count": 1}
    assert k["violations"]["qa"] == {"max": 1.0, "count": 2}
    assert k["control_effort"]["qa"]["integral_square"] == pytest.approx(10 * (1 + 9 + 1))
    assert k["control_effort"]["qa"]["total_variation"] == pytest.approx(2 + 4 + 1)
    assert k["tv"] == {"qa": pytest.approx(2 + 4 + 1)}
    assert k["worst_offset"] == {"h1": pytest.approx(0.2)}
    # two set-point intervals; the offset is averaged over each interval's second half
    assert k["setpoints"] == [
        {"start": 0.0, "end": 10.0, "ref": {"h1": 1.0}, "offset": {"h1": pytest.approx(-0.2)}},
        {"start": 20.0, "end": 30.0, "ref": {"h1": 2.0}, "offset": {"h1": pytest.approx(0.0)}},
    ]


def test_csv_follows_cross_check_conventions(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    write_csv(path, COLUMNS, ROWS)
    lines = path.read_text().splitlines()
    assert lines[0] == '"time","ref.h1","plant.h1","ctrl.qa","ctrl.cost"'
    assert lines[4] == "30.0,2.0,2.0,0.0,0.30000000000000004"  # full precision
    assert not any(line.endswith(",") for line in lines)
    back = list(csv.reader(lines))
    assert [float(x) for x in back[4]] == ROWS[3]  # round-trips exactly


def test_write_summary_and_figure(tmp_path: Path) -> None:
    result = RunResult(columns=COLUMNS, rows=[list(r) for r in ROWS], status="failed",
                       reason="plant: doStep at t=30.0 failed: x", steps=3, steps_planned=9,
                       step_size=10.0, stop_time=90.0, outputs=["h1"], references=["h1"],
                       inputs=["qa"], bounds={"h1": (0.0, 2.0), "qa": (0.0, 2.0)},
                       perturbation_times=[15.0], controller_summary={"solves": 4, "x": math.inf})
    doc = write(tmp_path, result, {"scenario": "s.csv", "controller": "pi"})
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk == doc
    assert doc["status"] == "failed" and doc["reason"].startswith("plant: doStep")
    assert doc["steps"] == 3 and doc["steps_planned"] == 9
    assert doc["controller"] == "pi"
    assert doc["controller_summary"] == {"solves": 4, "x": None}  # JSON has no inf
    assert list(doc["kpis"]) == ["iae", "final_error", "worst_offset", "violations", "tv",
                                 "control_effort", "setpoints"]
    assert doc["signals"] == {"outputs": {"h1": {"unit": "", "min": 0.0, "max": 2.0}},
                              "inputs": {"qa": {"unit": "", "min": 0.0, "max": 2.0}}}
    assert (tmp_path / "figure.png").stat().st_size > 10_000
    assert (tmp_path / "results.csv").read_text().count("\n") == 5


def test_flat_kpis_are_named_by_their_path_below_kpis() -> None:
    k = kpis.compute(COLUMNS, ROWS, ["h1"], ["h1"], ["qa"], {"h1": (0.0, 2.0), "qa": (0.0, 2.0)})
    flat = kpis.flat(k)
    assert list(flat) == ["iae.h1", "final_error.h1", "worst_offset.h1", "tv.qa",
                          "violations.h1.max", "violations.h1.count", "violations.qa.max",
                          "violations.qa.count"]
    for name, value in flat.items():
        doc: object = k
        for part in name.split("."):
            doc = doc[part]  # type: ignore[index]
        assert value == doc, name


def test_kpis_without_rows_or_set_points() -> None:
    empty = kpis.compute(["time", "plant.y", "ctrl.u"], [], ["y"], [], ["u"], {})
    assert kpis.flat(empty) == {}
    k = kpis.compute(["time", "plant.y", "ctrl.u"], [[0.0, 1.0, 2.0], [1.0, 1.5, 3.0]], ["y"],
                     [], ["u"], {"y": (0.0, 1.2)})
    assert kpis.flat(k) == {"tv.u": 1.0, "violations.y.max": pytest.approx(0.3),
                            "violations.y.count": 1.0}


def test_summed_kpis_are_in_units_of_the_boxes() -> None:
    """``kpis.summed``: a plant of any size as one number (each signal over its box width)."""
    summary = {"kpis": {"iae": {"T": 650.0, "CA": 0.9}, "tv": {"P": 4000.0}},
               "signals": {"outputs": {"T": {"min": 15.0, "max": 80.0},
                                       "CA": {"min": 0.1, "max": 1.0}},
                           "inputs": {"P": {"min": 0.0, "max": 2000.0}}}}
    assert kpis.summed(summary, "iae") == pytest.approx(650.0 / 65.0 + 0.9 / 0.9)
    assert kpis.summed(summary, "tv") == pytest.approx(2.0)
