"""Operator actions in co-simulation (issue 61): each action of a scenario's op.* columns, the
inputs the plant got row by row (plant.<input>) beside what the controller computed
(ctrl.<input>), the bumpless switch to auto (no input step beyond max_move), the audit log
operator.csv, a refused request at run time, a bad row before it (exit 2, file:line:column),
the PI under the same actions, and the commissioning in shadow (--mode manual)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.cli import main
from cosim.core.errors import CosimError
from tests.fourtank_problem import PATH

QA, QB = 9.05e-4, 11.1e-4
MAX_MOVE = 5e-5   # qa's move limit [m3/s per sample]
SCENARIO = ("time,ref.h1,ref.h2,op.mode,op.manual.qa,op.service.qb,op.max.qa,op.control.h2,"
            "op.max.h1\n") + """0,0.8,0.8,manual,3e-4,,,,
250,,,auto,,,,,
500,,,,,0,,,
750,,,,,1,6e-4,,
1000,,,,,,,0,1.2
1250,,,,,,,1,0.6
1500,,,,,,,,
"""


@pytest.fixture(scope="module")
def problem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The four-tank's problem with a move limit on qa."""
    path = tmp_path_factory.mktemp("ops") / "problem.toml"
    path.write_text(PATH.read_text().replace('description = "pump a flow"',
                                             f'description = "pump a flow"\nmax_move = {MAX_MOVE}'))
    return path


@pytest.fixture(scope="module")
def operated(problem: Path, tmp_path_factory: pytest.TempPathFactory) -> cosim.RunOutput:
    folder = tmp_path_factory.mktemp("operated")
    scenario = folder / "operated.csv"
    scenario.write_text(SCENARIO)
    return cosim.run(scenario, problem=problem, out=folder / "out", figure=False)


def _rows(run: cosim.RunOutput, t0: float, t1: float) -> list[dict]:
    return [r for r in run.to_pandas().to_dict("records") if t0 <= r["time"] < t1]


def test_manual_gives_the_plant_the_operators_inputs_and_predicts_in_shadow(
        operated: cosim.RunOutput) -> None:
    rows = _rows(operated, 0, 250)
    assert all(r["plant.qa"] == 3e-4 for r in rows)              # the operator's value
    assert len({r["plant.qb"] for r in rows}) == 1                # held where it was
    assert any(abs(r["ctrl.qa"] - r["plant.qa"]) > 1e-5 for r in rows)   # the shadow's own
    for r in rows[1:]:   # a plan starts from the plant's input, within max_move
        if not r["ctrl.fallback"]:
            assert abs(r["ctrl.qa"] - 3e-4) <= MAX_MOVE * (1 + 1e-9)


def test_the_switch_to_auto_is_bumpless(operated: cosim.RunOutput) -> None:
    """From the operator's input, every move of qa at most max_move (the switch included);
    qb (no move limit) moves freely."""
    qa = operated.to_pandas()["plant.qa"].to_numpy()
    assert np.max(np.abs(np.diff(qa))) <= MAX_MOVE * (1 + 1e-9)
    switch = _rows(operated, 225, 275)
    assert switch[0]["plant.qa"] == 3e-4 and switch[1]["plant.qa"] != 3e-4


def test_out_of_service_limits_and_outputs_dropped(operated: cosim.RunOutput) -> None:
    held = _rows(operated, 475, 750)
    assert len({r["plant.qb"] for r in held}) == 1                # out of service: held
    limited = _rows(operated, 750 + 25 * 7, 1500)                 # ramped by max_move
    assert max(r["plant.qa"] for r in limited) <= 6e-4 + 1e-12
    assert all(abs(r["plant.qa"] - r["ctrl.qa"]) < 1e-12 for r in limited)   # its own
    df = operated.to_pandas()
    assert {"plant.qa", "plant.qb", "ctrl.qa", "ctrl.qb"} <= set(df.columns)


def test_every_action_is_an_audit_row_and_a_refusal_keeps_the_setting(
        operated: cosim.RunOutput) -> None:
    rows = list(csv.DictReader((operated.out / "operator.csv").open()))
    assert [r["what"] for r in rows] == ["op.mode", "op.manual.qa", "op.mode", "op.service.qb",
                                         "op.service.qb", "op.max.qa", "op.control.h2",
                                         "op.max.h1", "op.control.h2", "op.max.h1"]
    assert {r["who"] for r in rows} == {"scenario"}
    refused = [r for r in rows if r["result"] != "accepted"]
    assert [(r["time"], r["what"], r["new"]) for r in refused] == [("1250.0", "op.max.h1",
                                                                   "0.6")]
    assert "no admissible steady output of h1" in refused[0]["result"]
    op = operated.summary["controller_summary"]["operator"]
    assert op["refused"] == 1 and op["final"]["limits"]["h1"][1] == 1.2
    assert [p["mode"] for p in op["periods"]][:2] == ["manual", "auto"]
    assert op["periods"][0]["guarantees"][0].startswith("manual")


def test_a_limit_outside_the_box_is_a_bad_row(problem: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "bad.csv"
    scenario.write_text("time,ref.h1,ref.h2,op.max.qa\n0,0.8,0.8,\n100,,,2e-3\n200,,,\n")
    code = main(["run", str(scenario), "--problem", str(problem), "--out", str(tmp_path / "o"),
                 "--quiet", "--no-figure"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err, err
    assert f"{scenario}:3:4: column 'op.max.qa': op.max.qa: 0.002 m3/s is outside" in err
    assert not (tmp_path / "o" / "results.csv").exists()


def test_the_pi_returns_bumplessly(tmp_path: Path) -> None:
    """The PI in manual tracks the operator's inputs with its integrators (back-calculated),
    so that the first auto step continues from them."""
    scenario = tmp_path / "pi.csv"
    scenario.write_text("time,ref.h1,ref.h2,op.mode,op.manual.qa,op.manual.qb\n"
                        "0,0.7,0.7,manual,4e-4,5e-4\n500,,,auto,,\n750,,,,,\n")
    df = cosim.run(scenario, controller="pi", figure=False).to_pandas()
    manual = df[df["time"] < 500]
    assert (manual["plant.qa"] == 4e-4).all() and (manual["plant.qb"] == 5e-4).all()
    at = df.index[df["time"] == 500][0]
    for u, box in (("qa", QA), ("qb", QB)):
        jump = abs(df[f"plant.{u}"][at] - df[f"plant.{u}"][at - 1])
        assert jump < 0.02 * box, (u, jump)


def test_a_pi_refuses_output_limits(tmp_path: Path) -> None:
    scenario = tmp_path / "pi.csv"
    scenario.write_text("time,ref.h1,ref.h2,op.max.h1\n0,0.7,0.7,1.0\n100,,,\n")
    with pytest.raises(CosimError, match=r":2:4: column 'op.max.h1': no setting 'op.max.h1'"):
        cosim.run(scenario, controller="pi", figure=False)


def test_a_shadow_run_reports_its_prediction_errors(tmp_path: Path) -> None:
    """``--mode manual``: the controller writes nothing of its own (the plant keeps the
    inputs it holds), and the summary gives, per output, its k-step prediction errors."""
    scenario = tmp_path / "shadow.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.8,0.8\n1000,,\n")
    run = cosim.run(scenario, mode="manual", figure=False)
    df = run.to_pandas()
    assert df["plant.qa"].nunique() == 1 and df["plant.qb"].nunique() == 1
    assert df["ctrl.qa"].nunique() > 1
    errors = run.summary["controller_summary"]["operator"]["prediction_error"]
    h1 = errors["outputs"]["h1"]
    assert errors["steps"] == len(df) and 0 < h1["rms"] < 0.2
    assert len(h1["rms_by_step"]) > 10 and h1["rms_by_step"][0] <= h1["rms_by_step"][-1]
