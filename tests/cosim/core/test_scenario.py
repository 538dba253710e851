"""Scenario CSV parsing and validation: every malformed case names file, line and column."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.core.scenario import BIAS, DIST, NOISE, PLANT, REF, load

ROOT = Path(__file__).resolve().parents[3]


def write(tmp_path: Path, text: str, name: str = "sc.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_parses_columns_events_and_times(tmp_path: Path) -> None:
    path = write(tmp_path, '"time","ref.h1",ref.h2,plant.qd1,sensor.h1.bias,sensor.h2.noise\n'
                           "0,0.8,0.7,,,\n"
                           "100,,0.9,-1e-5,0.02,\n"
                           "\n"
                           "250,,,,,0.01\n"
                           "400,,,,,\n")
    sc = load(path)
    assert [(c.index, c.kind, c.target) for c in sc.columns] == [
        (2, REF, "h1"), (3, REF, "h2"), (4, PLANT, "qd1"), (5, BIAS, "h1"), (6, NOISE, "h2")]
    assert sc.start_time == 0.0 and sc.stop_time == 400.0
    assert [e.time for e in sc.events] == [0.0, 100.0, 250.0, 400.0]
    assert [e.line for e in sc.events] == [2, 3, 5, 6]
    second = {c.name: v for c, v in sc.events[1].values}
    assert second == {"ref.h2": 0.9, "plant.qd1": -1e-5, "sensor.h1.bias": 0.02}
    assert sc.perturbation_times() == [100.0, 250.0]
    assert sc.reference_times() == [100.0]


@pytest.mark.parametrize(("text", "where", "words"), [
    ("", ":1:1:", "empty file"),
    ("t,ref.h1\n0,1\n1,\n", ":1:1:", "first column must be 'time'"),
    ("time,ref.h1,foo.h2\n0,1,2\n5,,\n", ":1:3:", "unknown signal 'foo.h2'"),
    ("time,ref.h1,sensor.h1.drift\n0,1,2\n5,,\n", ":1:3:", "unknown signal"),
    ("time,ref.h1,dist.a.b\n0,1,2\n5,,\n", ":1:3:", "expected ref.<output>, dist.<disturbance>"),
    ("time,ref.h1,dist.\n0,1,2\n5,,\n", ":1:3:", "unknown signal 'dist.'"),
    ("time,ref.h1,ref.h1\n0,1,1\n5,,\n", ":1:3:", "duplicate column 'ref.h1'"),
    ("time,ref.h1\n", ":2:1:", "empty body"),
    ("time,ref.h1\n0,1\n", ":2:1:", "single row"),
    ("time,ref.h1\n0,1\n10,2\n10,3\n", ":4:1:", "not after"),
    ("time,ref.h1\n0,1\n10,2\n5,3\n", ":4:1:", "not after"),
    ("time,ref.h1\n0,1\nten,2\n", ":3:1:", "'ten' is not a number"),
    ("time,ref.h1\n0,1\n,2\n", ":3:1:", "missing time"),
    ("time,ref.h1,ref.h2\n0,1,abc\n5,,\n", ":2:3:", "column 'ref.h2': 'abc' is not a number"),
    ("time,ref.h1,ref.h2\n0,1,1\n5,nan,\n9,,\n", ":3:2:", "column 'ref.h1': nan is not a finite"),
    ("time,ref.h1,plant.a1\n0,1,1\n5,,inf\n9,,\n", ":3:3:", "column 'plant.a1': inf"),
    ("time,ref.h1,ref.h2\n0,1,\n5,,1\n", ":2:3:", "ref.h2': a reference needs a value in "
                                                 "the first row"),
    ("time,ref.h1,sensor.h1.noise\n0,1,-0.1\n5,,\n", ":2:3:", "negative"),
    ("time,ref.h1\n0,1,2\n5,\n", ":2:3:", "row has 3 cells, the header has 2"),
    ("time,ref.h1,ref.h2\n0,1\n5,,\n", ":2:3:", "row has 2 cells"),
])
def test_malformed_scenarios_name_file_line_column(tmp_path: Path, text: str, where: str,
                                                   words: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(CosimError) as info:
        load(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}{where}"), msg
    assert words in msg
    assert "\n" not in msg


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match="scenario file not found"):
        load(tmp_path / "nope.csv")


def test_validate_reports_unknown_names_with_line_1_and_column(tmp_path: Path) -> None:
    path = write(tmp_path, "time,ref.h1,ref.h3,plant.qd1,plant.zz,sensor.h4.bias,plant.qa\n"
                           "0,1,1,0,0,0,0\n10,,,,,,\n")
    sc = load(path)
    settable = {"qa", "qb", "qd1", "a1", "h1_start"}
    ok = dict(plant_settable=settable, controller_refs={"h1", "h3"}, measured={"h1", "h4"})

    with pytest.raises(CosimError, match=r":1:3: unknown reference 'ref.h3'"):
        sc.validate(settable, {"h1", "h2"}, {"h1", "h4"})
    with pytest.raises(CosimError, match=r":1:5: unknown plant variable 'plant.zz'"):
        sc.validate(**ok)
    settable.add("zz")
    with pytest.raises(CosimError, match=r":1:6: unknown measured output in 'sensor.h4.bias'"):
        sc.validate(settable, {"h1", "h3"}, {"h1", "h2"})
    with pytest.raises(CosimError, match=r":1:7: column 'plant.qa' sets a plant input that the "
                                         "controller drives"):
        sc.validate(**ok, driven={"qa"})
    sc.validate(**ok, driven={"qb"})  # all known: no error


def test_a_disturbance_column_names_one_of_the_problems(tmp_path: Path) -> None:
    path = write(tmp_path, "time,ref.h1,dist.Tin\n0,1,290\n10,,300\n")
    sc = load(path)
    assert [(c.kind, c.target) for c in sc.columns] == [(REF, "h1"), (DIST, "Tin")]
    ok = dict(plant_settable={"Tin"}, controller_refs={"h1"}, measured={"h1"})
    sc.validate(**ok, disturbances={"Tin"})
    with pytest.raises(CosimError, match=r":1:3: unknown disturbance 'dist.Tin': the problem "
                                         r"measures dist.Tout"):
        sc.validate(**ok, disturbances={"Tout"})
    with pytest.raises(CosimError, match=r"measures none"):
        sc.validate(**ok)


def test_fixed_parameters_only_in_first_row(tmp_path: Path) -> None:
    path = write(tmp_path, "time,ref.h1,plant.h1_start\n0,1,0.7\n10,,0.9\n20,,\n")
    sc = load(path)
    sc.validate({"h1_start"}, {"h1"}, {"h1"})  # no tunable list given: not checked
    # the first row may set it (a start value), the second may not
    with pytest.raises(CosimError, match=r":3:3: column 'plant.h1_start'.*first row"):
        sc.validate({"h1_start"}, {"h1"}, {"h1"}, plant_tunable=set())
    good = write(tmp_path, "time,ref.h1,plant.h1_start\n0,1,0.7\n20,,\n", "good.csv")
    load(good).validate({"h1_start"}, {"h1"}, {"h1"}, plant_tunable=set())


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios").glob("*.csv")),
                         ids=lambda p: p.name)
def test_shipped_scenarios_parse(path: Path) -> None:
    sc = load(path)
    assert sc.stop_time > sc.start_time
    assert sc.columns_of(REF), "every shipped scenario sets references"


def test_paper_scenario_is_long_and_moderate() -> None:
    sc = load(ROOT / "scenarios" / "paper_steps.csv")
    assert (sc.stop_time - sc.start_time) / 25.0 >= 1500
    values = [v for e in sc.events for c, v in e.values if c.kind == REF]
    assert min(values) >= 0.5 and max(values) <= 1.4
    assert len(sc.reference_times()) >= 10


def test_with_changes_sets_first_row_replaces_setpoints_and_stop(tmp_path: Path) -> None:
    path = write(tmp_path, "time,ref.h1,ref.h2,plant.qd1\n0,0.8,0.7,0\n100,0.9,,-1e-5\n"
                           "300,,0.6,\n400,,,\n")
    sc = load(path)
    changed = sc.with_changes({"plant.qd1": 2e-5, "sensor.h1.uniform": 0.01},
                              [(0.0, {"h1": 1.1, "h2": 1.2}), (150.0, {"h1": 1.3})],
                              stop_time=350.0)
    assert changed.start_time == 0.0 and changed.stop_time == 350.0
    rows = [(e.time, {c.name: v for c, v in e.values}) for e in changed.events]
    assert rows == [
        (0.0, {"plant.qd1": 2e-5, "sensor.h1.uniform": 0.01, "ref.h1": 1.1, "ref.h2": 1.2}),
        (100.0, {"plant.qd1": -1e-5}),
        (150.0, {"ref.h1": 1.3}),
        (300.0, {}),
        (350.0, {}),
    ]
    assert [c.kind for c in changed.columns][-1] == "uniform"
    assert sc.stop_time == 400.0  # the original is unchanged
    with pytest.raises(CosimError, match="unknown signal 'plant'"):
        sc.with_changes({"plant": 1.0})
    with pytest.raises(CosimError, match="not after the start time"):
        sc.with_changes(stop_time=0.0)


def test_a_columns_schedule_holds_each_row_until_the_next(tmp_path: Path) -> None:
    """What a controller that knows a disturbance ahead is told: the value at any time, as
    the run sets it (a blank cell keeps the last; before the first, the default)."""
    path = tmp_path / "s.csv"
    path.write_text("time,ref.T,dist.T_in\n0,40,\n100,45,20\n200,50,\n300,50,15\n400,50,\n")
    at = load(path).schedule(DIST, "T_in", 18.0)
    assert [at(t) for t in (0.0, 99.9, 100.0, 250.0, 299.9999999999, 300.0, 1e6)] == [
        18.0, 18.0, 20.0, 20.0, 15.0, 15.0, 15.0]
    assert load(path).schedule(DIST, "T_out", 7.0)(250.0) == 7.0
