"""``benchmarks/oracle_bound.py``: the IAE oracle of the example heaters and the furnace with a
load in closed loop with their FMUs (its model is the plant's own, its solves all pass their
checks, it tracks)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import cosim

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks"
PROBLEM = ROOT / "fmus" / "examples" / "heater" / "problem.toml"


def _build(plant: str, folder: Path) -> Path:
    """The example plant's FMU (``fmus/examples/build.py``) in ``folder``."""
    spec = importlib.util.spec_from_file_location("examples_build",
                                                  ROOT / "fmus" / "examples" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(plant, folder)


@pytest.fixture(scope="module")
def heater_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _build("heater", tmp_path_factory.mktemp("heater"))


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
    fmu = _build("heater_dead_time", tmp_path / "fmu")
    problem = ROOT / "fmus" / "examples" / "heater_dead_time" / "problem.toml"
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.T,dist.T_in,plant.C_factor\n0,55,20,0.9\n600,,30,\n"
                        "1200,40,,\n1600,,10,\n2400,,,\n")
    run = cosim.run(scenario, plant=fmu, controller="oracle_bound:OracleController",
                    options={"plant": "heater_dead_time", "fmu": str(fmu),
                             "problem": str(problem), "horizon": 30,
                             "parameters": {"C_factor": 0.9}}, problem=problem)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["failures"] == 0 and info["steps"] == 121
    assert info["prediction_error_max"] < 1e-9
    df = run.to_pandas()
    T = df["plant.T"].to_numpy()
    assert abs(T[59] - 55) < 0.05 and abs(T[-1] - 40) < 0.05   # through the ambient steps


def test_the_oracle_knows_the_furnaces_measured_load(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The two-zone furnace with its product throughput stepping (an FMU input) and its heat
    capacity off nominal: the oracle's one-sample prediction is the plant's to rounding, the
    load draws heat from zone 1 (its power follows the load), and the oracle tracks through
    the load steps."""
    monkeypatch.syspath_prepend(str(BENCH))
    fmu = _build("furnace_load", tmp_path / "fmu")
    problem = ROOT / "fmus" / "examples" / "furnace_load" / "problem.toml"
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.T1,ref.T2,dist.load,plant.C_factor\n"
                        "0,160,150,10,0.9\n600,,,45,\n1200,,,0,\n1800,,,,\n")
    run = cosim.run(scenario, plant=fmu, controller="oracle_bound:OracleController",
                    options={"plant": "furnace_load", "fmu": str(fmu),
                             "problem": str(problem), "horizon": 30,
                             "parameters": {"C_factor": 0.9}}, problem=problem)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["failures"] == 0 and info["steps"] == 91
    assert info["prediction_error_max"] < 1e-9
    df = run.to_pandas()
    T1, T2, P1 = (df[c].to_numpy() for c in ("plant.T1", "plant.T2", "ctrl.P1"))
    assert abs(T1[29] - 160) < 0.1 and abs(T2[29] - 150) < 0.1
    assert abs(T1[-1] - 160) < 0.1 and abs(T2[-1] - 150) < 0.1   # through the load steps
    assert P1[58] > P1[28] + 500 and P1[88] < P1[28] - 100   # more power for more load
