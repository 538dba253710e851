"""The third-party example plant (``fmus/thirdparty``): pythonfmu build, model description,
physics, and its variable map with ``cosim run``."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
THIRDPARTY = ROOT / "fmus" / "thirdparty"
MAP = THIRDPARTY / "quadruple_tank.map.toml"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"thirdparty_{name}", THIRDPARTY / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _load("build").build(tmp_path_factory.mktemp("thirdparty"))


def test_build_script_cli_writes_a_valid_fmu(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(THIRDPARTY / "build.py"), "--out", str(tmp_path)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "QuadrupleTank.fmu").is_file()


def test_fmpy_validate_finds_no_problem(fmu: Path) -> None:
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmu)) == []


def test_model_description_has_other_names_and_units(fmu: Path) -> None:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    assert md.fmiVersion == "2.0" and md.generationTool.startswith("PythonFMU")
    var = {v.name: v for v in md.modelVariables}
    assert {n: var[n].causality for n in ("Fa", "Fb", "Fin1", "L1", "L4", "split_a")} == {
        "Fa": "input", "Fb": "input", "Fin1": "input", "L1": "output", "L4": "output",
        "split_a": "parameter"}
    assert var["Fa"].unit == "l/min" and var["L2"].unit == "cm" and var["outlet3"].unit == "cm2"
    assert "qa" not in var and "h1" not in var
    units = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert units["l/min"].m == 3 and units["l/min"].s == -1
    assert math.isclose(units["l/min"].factor, 1 / 60000) and units["cm"].factor == 0.01


def _simulate(fmu: Path, start: dict[str, float], stop: float = 2500.0) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), start_time=0.0, stop_time=stop, step_size=25.0,
                        output_interval=25.0, start_values=start,
                        output=["L1", "L2", "L3", "L4"])


def test_default_start_is_a_steady_state_at_65_cm(fmu: Path) -> None:
    qt = _load("quadruple_tank")
    a = [1e-4 * x for x in (1.35, 1.47, 0.90, 0.91)]
    h = qt.steady_state(0.65, 0.65, a, 0.35, 0.45)
    # Pump flows of that steady state (l/min), from tanks 3 and 4.
    qb = a[2] * math.sqrt(2 * qt.G * h[2]) / (1 - 0.45)
    qa = a[3] * math.sqrt(2 * qt.G * h[3]) / (1 - 0.35)
    res = _simulate(fmu, {"Fa": 60000 * qa, "Fb": 60000 * qb})
    for i in range(4):
        np.testing.assert_allclose(res[f"L{i + 1}"], 100 * h[i], rtol=1e-9)
    assert res["L1"][0] == pytest.approx(65.0)


def test_matches_an_accurate_ode_solution(fmu: Path) -> None:
    from scipy.integrate import solve_ivp

    qt = _load("quadruple_tank")
    a = [1e-4 * x for x in (1.35, 1.47, 0.90, 0.91)]
    qa, qb, qd1 = 30.0 / 60000, 40.0 / 60000, -1.0 / 60000  # l/min -> m3/s
    h0 = qt.steady_state(0.65, 0.65, a, 0.35, 0.45)

    def rhs(_t, h):
        o = [ai * math.sqrt(2 * 9.81 * max(hi, 0.0)) for ai, hi in zip(a, h, strict=True)]
        return [(-o[0] + o[2] + 0.35 * qa + qd1) / 0.062, (-o[1] + o[3] + 0.45 * qb) / 0.062,
                (-o[2] + 0.55 * qb) / 0.062, (-o[3] + 0.65 * qa) / 0.062]

    t = np.arange(0.0, 2501.0, 25.0)
    ref = solve_ivp(rhs, (0, 2500), h0, t_eval=t, rtol=1e-11, atol=1e-13, method="DOP853").y
    res = _simulate(fmu, {"Fa": 30.0, "Fb": 40.0, "Fin1": -1.0})
    for i in range(4):
        np.testing.assert_allclose(res[f"L{i + 1}"], 100 * ref[i], rtol=0, atol=1e-6)
    assert abs(res["L1"][-1] - res["L1"][0]) > 5.0  # it moved (cm)


def test_start_levels_and_parameters_are_settable(fmu: Path) -> None:
    res = _simulate(fmu, {"L1_0": 120.0, "L2_0": 0.0, "split_a": 0.5}, stop=25.0)
    assert res["L1"][0] == 120.0 and res["L2"][0] == 0.0 and res["L1"][1] < 120.0


@pytest.mark.slow
def test_cosim_run_with_the_map_and_pi(fmu: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2,plant.qd1,plant.gamma_a\n0,0.65,0.65,0,\n"
                        "500,0.8,,-1e-5,0.33\n1500,,,,\n")
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(scenario), "--plant",
                           str(fmu), "--map", str(MAP), "--controller", "pi", "--out",
                           str(tmp_path / "out"), "--quiet", "--no-figure"],
                          cwd=ROOT, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    from cosim.core.compare import read_table

    table = read_table(tmp_path / "out" / "results.csv")
    h1 = table.column("plant.h1")
    assert h1[0] == pytest.approx(0.65)                    # 65 cm converted to m
    assert 0.7 < h1[-1] < 0.9                              # PI drives it towards 0.8 m
    assert table.column("ctrl.qa").max() <= 9.05e-4 + 1e-12


def test_map_unit_mismatch_is_a_one_line_error(fmu: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.map.toml"
    bad.write_text(MAP.read_text().replace('variable = "L1"\nunit = "cm"',
                                           'variable = "L1"\nunit = "mm"'))
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n100,,\n")
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(scenario), "--plant",
                           str(fmu), "--map", str(bad), "--controller", "pi", "--out",
                           str(tmp_path / "out"), "--quiet", "--no-figure"],
                          cwd=ROOT, capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert "signal 'h1' -> variable 'L1': unit mismatch" in proc.stderr
    assert "'mm'" in proc.stderr and "'cm'" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_a_problem_with_variable_keys_binds_without_a_map(fmu: Path, tmp_path: Path) -> None:
    """The four-tank problem naming the FMU's variables (Fa, Fb, L1, L2) in its own units
    (m3/s, m; the FMU's l/min, cm): the same closed loop as through the variable map."""
    text = (ROOT / "fmus" / "fourtank" / "problem.toml").read_text()
    for signal, variable in (("qa", "Fa"), ("qb", "Fb"), ("h1", "L1"), ("h2", "L2")):
        kind = "inputs" if signal.startswith("q") else "outputs"
        text = text.replace(f"[{kind}.{signal}]\n", f'[{kind}.{signal}]\nvariable = "{variable}"\n')
    problem = tmp_path / "problem.toml"
    problem.write_text(text)
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.8,\n1500,,\n")
    tables = {}
    for name, how in (("map", ["--map", str(MAP)]), ("problem", ["--problem", str(problem)])):
        proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(scenario),
                               "--plant", str(fmu), *how, "--controller", "pi", "--out",
                               str(tmp_path / name), "--quiet", "--no-figure"],
                              cwd=ROOT, capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stderr
        from cosim.core.compare import read_table

        tables[name] = read_table(tmp_path / name / "results.csv")
    for col in ("plant.h1", "plant.h2", "ctrl.qa", "ctrl.qb"):
        a, b = tables["map"].column(col), tables["problem"].column(col)
        assert np.allclose(a, b, rtol=1e-9, atol=0), col
    assert tables["problem"].column("plant.h1")[0] == pytest.approx(0.65)   # cm -> m
