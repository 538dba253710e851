"""``benchmarks/oracle_bound.py``: the IAE oracle of the example heaters and the furnace with a
load in closed loop with their FMUs (its model is the plant's own, its solves all pass their
checks, it tracks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cosim
from tests import example_builds

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks"
PROBLEM = ROOT / "fmus" / "examples" / "heater" / "problem.toml"


@pytest.fixture(scope="module")
def heater_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return example_builds.build("heater", tmp_path_factory.mktemp("heater"))


def _disturbed_run(plant: str, folder: Path, scenario: str, steps: int) -> pd.DataFrame:
    """The oracle of example plant ``plant`` (heat capacity 0.9 of nominal, as the scenario's
    ``plant.C_factor`` sets it on the FMU) in closed loop on ``scenario``: every solve passes
    its checks, its one-sample prediction is the plant's to rounding; the results."""
    fmu = example_builds.build(plant, folder / "fmu")
    problem = example_builds.problem_file(plant)
    path = folder / "steps.csv"
    path.write_text(scenario)
    run = cosim.run(path, plant=fmu, controller="oracle_bound:OracleController",
                    options={"plant": plant, "fmu": str(fmu), "problem": str(problem),
                             "horizon": 30, "parameters": {"C_factor": 0.9}}, problem=problem)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["failures"] == 0 and info["steps"] == steps
    assert info["prediction_error_max"] < 1e-9
    return run.to_pandas()


def test_the_oracle_knows_the_plant_and_tracks(heater_fmu: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(BENCH))
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.T\n0,55\n800,35\n1600,\n")
    run = cosim.run(scenario, plant=heater_fmu, controller="oracle_bound:OracleController",
                    options={"plant": "heater", "fmu": str(heater_fmu), "problem": str(PROBLEM),
                             "horizon": 30}, problem=PROBLEM)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["failures"] == 0 and info["steps"] == 81
    assert info["prediction_error_max"] < 1e-9          # the plant's own equations and RK4
    df = run.to_pandas()
    T, P = df["plant.T"].to_numpy(), df["ctrl.P"].to_numpy()
    assert np.all((P >= -1e-9) & (P <= 2000 + 1e-9))
    assert abs(T[39] - 55) < 0.05 and abs(T[-1] - 35) < 0.05   # each set-point reached
    assert P[0] == pytest.approx(2000.0, abs=1e-6)             # full power towards 55 degC


def test_the_oracle_knows_the_dead_time_and_the_measured_disturbance(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The heater whose power acts 40 s late, its ambient temperature stepping and its heat
    capacity off nominal: the oracle's one-sample prediction is the plant's to rounding (the
    power still in the pipe and the ambient temperature measured now), and it tracks."""
    monkeypatch.syspath_prepend(str(BENCH))
    df = _disturbed_run("heater_dead_time", tmp_path,
                        "time,ref.T,dist.T_in,plant.C_factor\n0,55,20,0.9\n600,,30,\n"
                        "1200,40,,\n1600,,10,\n2400,,,\n", 121)
    T = df["plant.T"].to_numpy()
    assert abs(T[59] - 55) < 0.05 and abs(T[-1] - 40) < 0.05   # through the ambient steps


def test_the_oracle_knows_the_furnaces_measured_load(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The two-zone furnace with its product throughput stepping (an FMU input) and its heat
    capacity off nominal: the oracle's one-sample prediction is the plant's to rounding, the
    load draws heat from zone 1 (its power follows the load), and the oracle tracks through
    the load steps."""
    monkeypatch.syspath_prepend(str(BENCH))
    df = _disturbed_run("furnace_load", tmp_path,
                        "time,ref.T1,ref.T2,dist.load,plant.C_factor\n"
                        "0,160,150,10,0.9\n600,,,45,\n1200,,,0,\n1800,,,,\n", 91)
    T1, T2, P1 = (df[c].to_numpy() for c in ("plant.T1", "plant.T2", "ctrl.P1"))
    assert abs(T1[29] - 160) < 0.1 and abs(T2[29] - 150) < 0.1
    assert abs(T1[-1] - 160) < 0.1 and abs(T2[-1] - 150) < 0.1   # through the load steps
    assert P1[58] > P1[28] + 500 and P1[88] < P1[28] - 100   # more power for more load
