"""``cosim run`` end to end: shipped scenarios, swap-in FMU, malformed input, faults."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main

ROOT = Path(__file__).resolve().parents[3]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.csv"))


def run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(["run", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def load_csv(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True, deletechars="")
    return {name: data[name] for name in data.dtype.names}


def test_help_is_complete() -> None:
    top = subprocess.run([sys.executable, "-m", "cosim.cli", "--help"], capture_output=True,
                         text=True, check=True).stdout
    assert "run" in top and "exit codes" in top
    text = subprocess.run([sys.executable, "-m", "cosim.cli", "run", "--help"],
                          capture_output=True, text=True, check=True).stdout
    for option in ("SCENARIO", "--plant", "--map", "--controller", "--out", "--interface",
                   "--isolate", "--quiet", "--seed", "--step", "results.csv", "summary.json",
                   "figure.png", "exit codes"):
        assert option in text, option


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_with_pi(scenario: Path, tmp_path: Path, fmu2_path: Path,
                                   capsys: pytest.CaptureFixture) -> None:
    code, out, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                         "--out", str(tmp_path), "--quiet")
    assert code == 0, err
    assert out == "" and err == ""
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["steps"] == summary["steps_planned"] > 300
    assert all(v["count"] == 0 for v in summary["kpis"]["violations"].values())
    assert summary["kpis"]["iae"]["h1"] > 0 and summary["controller"] == "pi"
    r = load_csv(tmp_path / "results.csv")
    assert len(r["time"]) == summary["steps"] + 1
    # the PI settles: the last set-point is tracked
    assert abs(r["ref.h1"][-1] - r["plant.h1"][-1]) < 0.02
    assert (tmp_path / "figure.png").stat().st_size > 20_000


@pytest.mark.parametrize("extra", [["--interface", "me"], ["--isolate"], ["--fmi3"]],
                         ids=["me", "isolate", "fmi3"])
def test_variants_reproduce_the_reference_run(extra: list[str], tmp_path: Path,
                                              fmu2_path: Path, fmu3_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "leak_tank1.csv")
    base = ["--controller", "pi", "--quiet", "--no-figure"]
    assert run(capsys, scenario, *base, "--plant", str(fmu2_path), "--out",
               str(tmp_path / "a"))[0] == 0
    plant = str(fmu3_path) if extra == ["--fmi3"] else str(fmu2_path)
    extra = [] if extra == ["--fmi3"] else extra
    assert run(capsys, scenario, *base, "--plant", plant, "--out", str(tmp_path / "b"),
               *extra)[0] == 0
    a, b = load_csv(tmp_path / "a" / "results.csv"), load_csv(tmp_path / "b" / "results.csv")
    tol = 2e-5 if extra == ["--interface", "me"] else 0.0
    assert np.abs(a["plant.h1"] - b["plant.h1"]).max() <= tol


def test_same_run_twice_is_identical(tmp_path: Path, fmu2_path: Path,
                                     capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "sensor_noise.csv")
    for out in ("a", "b"):
        assert run(capsys, scenario, "--controller", "pi", "--plant", str(fmu2_path), "--quiet",
                   "--no-figure", "--seed", "7", "--out", str(tmp_path / out))[0] == 0
    assert (tmp_path / "a" / "results.csv").read_bytes() == \
        (tmp_path / "b" / "results.csv").read_bytes()


def test_swap_in_pythonfmu3_plant_with_a_unit_map(tmp_path: Path, pyfmu_dir: Path,
                                                  fmu2_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "sensor_bias.csv")
    code, _, err = run(capsys, scenario, "--controller", "pi", "--quiet", "--out",
                       str(tmp_path / "swap"), "--plant", str(pyfmu_dir / "QuadTank.fmu"),
                       "--map", str(pyfmu_dir / "quadtank.map.toml"))
    assert code == 0, err
    assert run(capsys, scenario, "--controller", "pi", "--quiet", "--no-figure", "--out",
               str(tmp_path / "ours"), "--plant", str(fmu2_path))[0] == 0
    swap, ours = load_csv(tmp_path / "swap" / "results.csv"), \
        load_csv(tmp_path / "ours" / "results.csv")
    # the map converted l/min <-> m3/s and cm <-> m: same closed loop as on our FMU
    assert np.abs(swap["plant.h1"] - ours["plant.h1"]).max() < 1e-4
    assert np.abs(swap["ctrl.qa"] - ours["ctrl.qa"]).max() < 1e-7
    assert np.abs(swap["plant.L4"] / 100 - ours["plant.h4"]).max() < 1e-4
    summary = json.loads((tmp_path / "swap" / "summary.json").read_text())
    assert summary["fmi_version"].startswith("3") and summary["map"].endswith(".toml")


def test_swap_in_map_errors(tmp_path: Path, pyfmu_dir: Path,
                            capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "sensor_bias.csv")
    bad = tmp_path / "bad.map.toml"
    bad.write_text((pyfmu_dir / "quadtank.map.toml").read_text().replace('"cm"', '"mm"', 1))
    code, _, err = run(capsys, scenario, "--controller", "pi", "--out", str(tmp_path / "x"),
                       "--plant", str(pyfmu_dir / "QuadTank.fmu"), "--map", str(bad))
    assert code == 2
    assert err.strip() == (f"cosim run: error: {bad}: signal 'h1' -> variable 'L1': unit "
                           "mismatch: the map expects 'mm', the FMU declares 'cm'")
    code, _, err = run(capsys, scenario, "--controller", "pi", "--out", str(tmp_path / "x"),
                       "--plant", str(pyfmu_dir / "QuadTank.fmu"))
    # without the map the four-tank problem's signals are looked up under their own names
    assert code == 2 and err.count("\n") == 1
    assert ("fourtank/problem.toml:10: input 'qa' -> FMU variable 'qa': QuadTank.fmu has no "
            "such variable") in err
    assert not (tmp_path / "x").exists()


def test_thirdparty_example_if_shipped(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    builder = ROOT / "fmus" / "thirdparty" / "build.py"
    map_file = ROOT / "fmus" / "thirdparty" / "quadruple_tank.map.toml"
    if not (builder.is_file() and map_file.is_file()):
        pytest.skip("fmus/thirdparty not shipped in this tree")
    import importlib.util

    spec = importlib.util.spec_from_file_location("thirdparty_build", builder)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    fmu = module.build(tmp_path / "fmu")
    code, _, err = run(capsys, str(ROOT / "scenarios" / "sensor_bias.csv"), "--controller", "pi",
                       "--quiet", "--no-figure", "--out", str(tmp_path / "r"),
                       "--plant", str(fmu), "--map", str(map_file))
    assert code == 0, err


MALFORMED = {
    "unknown_signal": ("time,ref.h1,ref.h2,plant.valve\n0,1,1,0\n100,,,\n", ":1:4:"),
    "unknown_reference": ("time,ref.h1,ref.h3\n0,1,1\n100,,\n", ":1:3:"),
    "non_increasing": ("time,ref.h1,ref.h2\n0,1,1\n100,,\n100,,\n", ":4:1:"),
    "non_numeric": ("time,ref.h1,ref.h2\n0,1,one\n100,,\n", ":2:3:"),
    "nan": ("time,ref.h1,ref.h2\n0,1,1\n50,NaN,\n100,,\n", ":3:2:"),
    "missing_first_reference": ("time,ref.h1,ref.h2\n0,,1\n100,1,\n", ":2:2:"),
    "empty_body": ("time,ref.h1,ref.h2\n", ":2:1:"),
}


def test_control_characters_in_a_file_reach_the_terminal_escaped(
        tmp_path: Path, fmu2_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A cell with an escape sequence or a bidirectional override: one line, the characters
    written as escapes, never sent to the terminal as they are. A quoted cell that spans
    lines is refused (it was read as its lines joined: "0.6\\n1" as 0.61)."""
    for cell, why in (("\x1b[31m", "'\\x1b[31m' is not a number"),
                      ("\u202e0.7", "'\\u202e0.7' is not a number"),
                      ('"0.6\r\n1"', "malformed CSV: a quoted cell spans lines 2 to 3"),
                      ('"0.6\n1"', "malformed CSV: a quoted cell spans lines 2 to 3")):
        path = tmp_path / "s.csv"
        path.write_bytes(f"time,ref.h1,ref.h2\n0,1,{cell}\n100,,\n".encode())
        code, _out, err = run(capsys, str(path), "--controller", "pi", "--plant",
                              str(fmu2_path), "--out", str(tmp_path / "out"))
        assert code == 2 and err.count("\n") == 1 and err.endswith("\n"), repr(err)
        assert err[:-1].isprintable() and why in err, repr(err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_scenarios_exit_2_with_location(case: str, tmp_path: Path, fmu2_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    text, where = MALFORMED[case]
    path = tmp_path / f"{case}.csv"
    path.write_text(text)
    code, _out, err = run(capsys, str(path), "--controller", "pi", "--plant", str(fmu2_path),
                         "--out", str(tmp_path / "out"))
    assert code == 2
    assert err.startswith(f"cosim run: error: {path}{where}") and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_fmu_failing_mid_run_keeps_partial_results(tmp_path: Path, pyfmu_dir: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    code, _, err = run(capsys, str(ROOT / "scenarios" / "sensor_bias.csv"), "--controller", "pi",
                       "--plant", str(pyfmu_dir / "Failing.fmu"), "--out", str(tmp_path))
    assert code == 1
    assert err.startswith("cosim run: failed: Failing.fmu: doStep at t=500.0 failed:")
    assert "tank ruptured" in err and "20 of 400 steps" in err and err.count("\n") == 1
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "tank ruptured" in summary["reason"]
    assert summary["steps"] == 20
    r = load_csv(tmp_path / "results.csv")
    assert list(r["time"]) == [25.0 * k for k in range(21)]
    assert (tmp_path / "figure.png").exists()


def test_segfaulting_fmu_with_isolate(tmp_path: Path, pyfmu_dir: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    code, _, err = run(capsys, str(ROOT / "scenarios" / "sensor_bias.csv"), "--controller", "pi",
                       "--plant", str(pyfmu_dir / "Segfault.fmu"), "--isolate", "--no-figure",
                       "--out", str(tmp_path))
    assert code == 1
    assert "Segfault.fmu: doStep at t=500.0 failed: worker died (signal 11" in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["steps"] == 20
    assert len(load_csv(tmp_path / "results.csv")["time"]) == 21


def test_bad_options(tmp_path: Path, fmu2_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "leak_tank1.csv")
    code, _, err = run(capsys, scenario, "--controller", "nope", "--plant", str(fmu2_path))
    assert code == 2 and "unknown controller 'nope'" in err
    code, _, err = run(capsys, scenario, "--controller", "pi", "--plant", str(tmp_path / "x.fmu"))
    assert code == 2 and "FMU not found" in err
    code, _, err = run(capsys, scenario, "--controller", "pi", "--plant", str(fmu2_path),
                       "--map", str(tmp_path / "none.toml"))
    assert code == 2 and "variable map not found" in err
    code, _, err = run(capsys, scenario, "--controller", "pi", "--plant", str(fmu2_path),
                       "--option", "gain=3")
    assert code == 2 and "controller 'pi' has no option 'gain'" in err
    bad_model = tmp_path / "bad.json"
    bad_model.write_text('{"format": "gru-mpc-model",\n "W_z": [[1, 2]\n')
    code, _, err = run(capsys, scenario, "--plant", str(fmu2_path), "--model", str(bad_model))
    assert code == 2 and f"{bad_model}:3:1: invalid JSON" in err and "Traceback" not in err


def test_controller_options_reach_the_controller(tmp_path: Path, fmu2_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    scenario = str(ROOT / "scenarios" / "leak_tank1.csv")
    code, _, _ = run(capsys, scenario, "--controller", "pi", "--plant", str(fmu2_path),
                     "--option", "pairing=diagonal", "--out", str(tmp_path), "--quiet")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 0 and summary["controller_options"] == {"pairing": "diagonal"}
    assert summary["controller_summary"]["pairing"] == {"h1": "qa", "h2": "qb"}


def test_swap_in_parameter_change_through_the_map(tmp_path: Path, pyfmu_dir: Path,
                                                  fmu2_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    """``plant.gamma_a`` reaches the swap-in FMU's ``gammaA``; ``plant.gammaA`` works too."""
    results = {}
    for name, column, plant, vmap in [
            ("ours", "plant.gamma_a", fmu2_path, None),
            ("mapped", "plant.gamma_a", pyfmu_dir / "QuadTank.fmu",
             pyfmu_dir / "quadtank.map.toml"),
            ("raw", "plant.gammaA", pyfmu_dir / "QuadTank.fmu", pyfmu_dir / "quadtank.map.toml")]:
        sc = tmp_path / f"{name}.csv"
        sc.write_text(f"time,ref.h1,ref.h2,{column}\n0,0.8,0.8,\n1000,,,0.36\n3000,,,\n")
        argv = [str(sc), "--controller", "pi", "--quiet", "--no-figure", "--plant", str(plant),
                "--out", str(tmp_path / name)]
        if vmap is not None:
            argv += ["--map", str(vmap)]
        code, _, err = run(capsys, *argv)
        assert code == 0, err
        results[name] = load_csv(tmp_path / name / "results.csv")
    for name in ("mapped", "raw"):
        assert np.abs(results[name]["plant.h2"] - results["ours"]["plant.h2"]).max() < 1e-4
    assert results["raw"]["plant.gammaA"][-1] == 0.36


SHORT = "time,ref.h1,ref.h2\n0,0.65,0.65\n100,,\n"


@pytest.mark.parametrize("step, message", [
    ("-5", "--step -5.0: the communication step must be a positive, finite number"),
    ("0", "--step 0.0: the communication step must be a positive, finite number"),
    ("nan", "--step nan: the communication step must be a positive, finite number"),
    ("1e-9", "--step 1e-09: 1e+11 communication steps of 1e-09 s from 0.0 s to 100.0 s, "
             "more than the 1000000 allowed"),
])
def test_bad_step_exit_2_before_running(step: str, message: str, tmp_path: Path,
                                        fmu2_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       f"--step={step}", "--out", str(tmp_path / "out"))
    assert code == 2 and err.startswith(f"cosim run: error: {message}")
    assert err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_out_that_is_a_file_exit_2_before_running(tmp_path: Path, fmu2_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file")
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       "--out", str(blocker))
    assert code == 2 and err == f"cosim run: error: {blocker}: --out must be a folder, but this " \
                                "is a file\n"
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       "--out", str(blocker / "sub"))
    assert code == 2 and err == f"cosim run: error: {blocker / 'sub'}: --out: '{blocker}' is not " \
                                "a folder\n"
    assert blocker.read_text() == "a file"


def test_negative_seed_exit_2(tmp_path: Path, fmu2_path: Path,
                              capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2,sensor.h1.noise\n0,0.65,0.65,0.01\n100,,,\n")
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       "--seed", "-1", "--out", str(tmp_path / "out"))
    assert code == 2 and err == "cosim run: error: --seed must be a non-negative integer, got -1\n"


def test_plant_for_another_platform_exit_2(tmp_path: Path, fmu2_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    import zipfile

    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    fmu = tmp_path / "win.fmu"
    with zipfile.ZipFile(fmu2_path) as zin, zipfile.ZipFile(fmu, "w") as zout:
        for info in zin.infolist():
            if not info.filename.startswith("binaries/"):
                zout.writestr(info, zin.read(info))
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu),
                       "--out", str(tmp_path / "out"))
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"cosim run: error: {fmu}: no binary for this platform: ")
    assert "(it has no binaries)" in err


@pytest.mark.parametrize("option, message", [
    ('pairing="sideways"', "controller 'pi': unknown pairing 'sideways' (the problem's: "
                           "cross, diagonal)"),
    ('initial_inputs={"qa": "x"}', "controller 'pi': initial_inputs: qa must be a finite "
                                   "number, got 'x'"),
    ('initial_inputs={"qz": 1}', "controller 'pi': initial_inputs: unknown input 'qz'"),
])
def test_bad_pi_options_exit_2(option: str, message: str, tmp_path: Path, fmu2_path: Path,
                               capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       "--option", option, "--out", str(tmp_path / "out"))
    assert code == 2 and err.startswith(f"cosim run: error: {message}") and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option, message", [
    ("N=2.5", "horizon N must be an integer >= 1, got 2.5"),
    ("N=true", "horizon N must be an integer >= 1, got True"),
    ("N=100000", "horizon N must be >= 1 and <= 1000, got 100000"),
    ('R="abc"', "option R='abc': expected a number, a 2x2 matrix or an object by input name"),
    ("R=-1", "cost weight R must be symmetric positive definite"),     # -1 times I
    ("R=[1,2,3]", "option R: expected a number or a 2x2 matrix, got shape (3,)"),
    ("R=[[0.01,0],[0,-0.01]]", "cost weight R must be symmetric positive definite"),
    ('gain_scale="x"', "gain scale must be a non-negative number, got 'x'"),
    ("R=NaN", "option R=nan: expected finite numbers"),
    ('R={"qa": Infinity}', "option R={'qa': inf}: expected finite numbers"),
])
def test_bad_robust_mpc_options_exit_2(option: str, message: str, tmp_path: Path,
                                       fmu2_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    code, _, err = run(capsys, str(scenario), "--plant", str(fmu2_path), "--option", option,
                       "--out", str(tmp_path / "out"))
    assert code == 2 and err == f"cosim run: error: {message}\n"
    assert not (tmp_path / "out").exists()


def test_scenario_too_long_for_memory_exit_2(tmp_path: Path, fmu2_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n\n1e12,,\n")
    code, _, err = run(capsys, str(scenario), "--controller", "pi", "--plant", str(fmu2_path),
                       "--out", str(tmp_path / "out"))
    assert code == 2 and err == (f"cosim run: error: {scenario}:4:1: 4e+10 communication steps "
                                 "of 25.0 s from 0.0 s to 1000000000000.0 s, more than the "
                                 "1000000 allowed\n")


@pytest.mark.parametrize("entry, signal, variable", [
    ('[signals.h3]\nvariable = "level3"\n', "h3", "level3"),   # an output nobody reads
    ('[signals.qd1]\nvariable = "Fin1"\n', "qd1", "Fin1"),     # an input the scenario leaves
])
def test_typo_in_an_unused_map_entry_exit_2_before_running(
        entry: str, signal: str, variable: str, tmp_path: Path, pyfmu_dir: Path,
        capsys: pytest.CaptureFixture) -> None:
    """Every map entry is checked against the FMU, whether the run uses it or not."""
    bad = tmp_path / "typo.map.toml"
    bad.write_text((pyfmu_dir / "quadtank.map.toml").read_text() + entry)
    code, out, err = run(capsys, str(ROOT / "scenarios" / "sensor_bias.csv"), "--controller",
                         "pi", "--out", str(tmp_path / "x"), "--plant",
                         str(pyfmu_dir / "QuadTank.fmu"), "--map", str(bad))
    assert code == 2 and out == ""
    assert err == (f"cosim run: error: {bad}: signal '{signal}' -> variable '{variable}': "
                   "the FMU has no such variable\n")
    assert not (tmp_path / "x").exists()


def test_model_with_saturated_update_gate_exit_2_naming_sigma_z(
        tmp_path: Path, fmu2_path: Path, capsys: pytest.CaptureFixture) -> None:
    """b_z = 40 everywhere: σ̄_z rounds to 1 and ν divides by 1 − σ̄_z = 0."""
    doc = json.loads((ROOT / "controllers" / "models" / "fourtank_gru.json").read_text())
    doc["b_z"] = [40.0] * len(doc["b_z"])
    model = tmp_path / "saturated.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    scenario.write_text(SHORT)
    code, out, err = run(capsys, str(scenario), "--plant", str(fmu2_path), "--model",
                         str(model), "--out", str(tmp_path / "out"))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert err.startswith(f"cosim run: error: {model}: sigma_z (σ̄_z = σ(‖[W_z U_z b_z]‖∞) = σ(")
    assert "rounds to 1" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_gru_model_as_the_plant(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    model = ROOT / "controllers" / "models" / "fourtank_gru.json"
    sc = tmp_path / "sc.csv"
    sc.write_text("time,ref.h1,ref.h2,plant.h1_start,plant.w_y_max\n0,0.8,0.8,0.75,0.01\n"
                  "500,,,,\n")
    code, _, err = run(capsys, str(sc), "--plant", f"model:{model}", "--controller", "pi",
                       "--out", str(tmp_path / "out"), "--quiet", "--no-figure", "--seed", "4")
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["plant"] == f"model:{model}" and summary["status"] == "ok"
    r = load_csv(tmp_path / "out" / "results.csv")
    assert abs(r["plant.h1"][0] - 0.75) <= 0.01 + 1e-9  # the start output, ± the noise bound
    code, _, err = run(capsys, str(sc), "--plant", f"model:{model}", "--isolate",
                       "--out", str(tmp_path / "o2"))
    assert code == 2 and "takes no --map, --isolate" in err
