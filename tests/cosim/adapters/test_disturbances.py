"""Measured disturbances through the workflow, on the example heater with its ambient
temperature measured (a tunable parameter of the FMU): ``generate-data`` excites it and logs its
column, ``train`` makes it a model input and says what measuring it is worth, a scenario's
``dist.T_in`` sets it on the plant and is recorded, the PI adds its static feedforward, and the
robust MPC (tracking law, compiled kernel and numpy alike; the paper's law) holds it over its
horizon. The heater whose power acts two samples late: :mod:`test_dead_time`."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from cosim.cli import main
from tests import example_builds
from tests.cosim.adapters.heaters import PAPER, iae, replay_paper_law, run_cache, trained
from tests.heater_problem import HEATER

PROBLEM = HEATER + """\

[mpc]
Q = "outputs"
R = 0.001
du_weight = 0
"""
#: a set-point step, then ambient steps down and up at a constant set-point
SCENARIO = "time,ref.T,dist.T_in\n0,40,20\n1000,55,20\n3000,55,10\n5000,55,30\n7000,55,30\n"


@pytest.fixture(scope="module")
def heater(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The heater FMU, its problem with the ambient measured, data and a briefly trained
    model."""
    folder = tmp_path_factory.mktemp("heater_d")
    fmu = example_builds.build("heater", folder)
    (folder / "heater.toml").write_text(PROBLEM)
    (folder / "steps.csv").write_text(SCENARIO)
    return {"fmu": fmu, "folder": folder, "scenario": folder / "steps.csv",
            **trained(folder, fmu, folder / "heater.toml", steps=3000, epochs=40)}


@pytest.fixture(scope="module")
def runs(heater: dict[str, Path]) -> Any:
    """The robust MPC's runs of the heater's scenario, each run once (:func:`run_cache`)."""
    return run_cache(heater)


def test_generate_data_excites_the_disturbance_and_train_makes_it_an_input(
        heater: dict[str, Path]) -> None:
    with open(heater["data"], newline="") as fh:
        header = next(csv.reader(fh))
    assert header == ["time", "P", "T_in", "T", "split"]
    data = np.genfromtxt(heater["data"], delimiter=",", names=True, dtype=None,
                         encoding="utf-8")
    t_in = data["T_in"]
    assert t_in.min() >= 5.0 and t_in.max() <= 35.0 and len(np.unique(t_in)) > 20
    doc = json.loads(heater["model"].read_text())
    assert [s["name"] for s in doc["inputs"]] == ["P", "T_in"]
    assert doc["problem"]["disturbances"][0]["variable"] == "T_amb"
    # the report: held at their mean the disturbances make the model far worse (the plant
    # follows its ambient), and the data's largest change per sample is recorded
    assert doc["training"]["without_disturbances"]["ratio"] > 3.0
    assert doc["training"]["disturbance_rates"]["T_in"] > 1.0


def test_a_scenario_sets_the_disturbance_on_the_plant_and_records_it(
        heater: dict[str, Path], tmp_path: Path) -> None:
    runs = {}
    for ff in ("true", "false"):
        out = tmp_path / f"pi_{ff}"
        assert main(["run", str(heater["scenario"]), "--plant", str(heater["fmu"]),
                     "--controller", "pi", "--model", str(heater["model"]), "--option",
                     f"feedforward={ff}", "--out", str(out), "--quiet"]) == 0
        runs[ff] = pd.read_csv(out / "results.csv")
        summary = json.loads((out / "summary.json").read_text())["controller_summary"]
        assert (summary["feedforward"] is not None) is (ff == "true")
    with_ff, without = runs["true"], runs["false"]
    assert with_ff["dist.T_in"].tolist()[::50] == [20.0] * 3 + [10.0] * 2 + [30.0] * 3
    # the ambient moves the plant: at the same set-point the PI needs more power when colder
    P = without.set_index("time")["ctrl.P"]
    assert P[2980.0] < P[4980.0] > P[6980.0]
    # the feedforward rejects the ambient steps far better, the set-point step alike
    for start, end in ((3000, 5000), (5000, 7001)):
        assert iae(with_ff, start, end) < 0.5 * iae(without, start, end)
    assert iae(with_ff, 0, 3000) == pytest.approx(iae(without, 0, 3000), rel=1e-9)


def test_the_robust_mpc_holds_the_measured_disturbance(heater: dict[str, Path],
                                                       tmp_path: Path) -> None:
    results = {}
    for kernel in ("auto", "numpy"):
        out = tmp_path / f"mpc_{kernel}"
        assert main(["run", str(heater["scenario"]), "--plant", str(heater["fmu"]),
                     "--model", str(heater["model"]), "--option", f'kernel="{kernel}"',
                     "--out", str(out), "--quiet"]) == 0
        summary = json.loads((out / "summary.json").read_text())
        ctrl = summary["controller_summary"]
        assert ctrl["disturbances"] == ["T_in"] and ctrl["disturbance_clipped"] == 0
        assert ctrl["kernel"] == ("compiled" if kernel == "auto" else "numpy")
        assert summary["kpis"]["violations"]["T"]["count"] == 0
        results[kernel] = pd.read_csv(out / "results.csv")
    compiled, numpy_ = results["auto"], results["numpy"]
    # the kernel's SQP and casadi's on the numpy derivatives: the same closed loop, nearly
    assert iae(compiled, 0, 7001) == pytest.approx(iae(numpy_, 0, 7001), rel=0.1)
    # it reacts to the ambient at once (feedforward): more power the step it gets colder
    at = compiled.set_index("time")
    P, T = at["ctrl.P"], at["plant.T"]
    assert P[3000.0] > P[2980.0] + 100.0 and P[5000.0] < P[4980.0] - 100.0
    # and tracks the set-point after each step
    for t in (2980.0, 4980.0, 6980.0):
        assert abs(T[t] - 55.0) < 0.5, t


def test_the_kernels_shift_of_the_biases_is_the_full_models(heater: dict[str, Path]) -> None:
    from controllers import gru
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=heater["model"])
    full, fh = ctrl.mpc.full_model, ctrl.mpc.fhocp
    assert fh.kernel is not None
    u = np.random.default_rng(0).uniform(-1, 1, (fh.N, 1))
    x0 = np.full(full.n, 0.1)
    for d in (0.7, -0.4, 0.0):
        ctrl.mpc.held.hold(np.array([d]), ctrl.mpc.fhocp)
        want = gru.simulate(full.params, x0, np.hstack([u, np.full((fh.N, 1), d)]))[0]
        assert np.max(np.abs(fh.simulate(x0, u) - want)) < 1e-13, d
        assert np.max(np.abs(gru.simulate(ctrl.mpc.model.params, x0, u)[0] - want)) < 1e-13, d
        # the observer's step (eq:observer, no correction when y = ŷ) at the disturbance too
        ctrl.mpc.observer.reset(x0=x0)
        ctrl.mpc.observer.make_step(u[0], ctrl.mpc.observer.y_hat())
        assert np.max(np.abs(ctrl.mpc.observer.x_hat - want[1])) < 1e-13, d


def test_the_paper_law_holds_the_measured_disturbance(runs: Any) -> None:
    """The paper's law computes its reference (x_bar, u_bar) again when the measured ambient
    moves: its power follows at once (the model's static feedforward), the set-point is held
    through both ambient steps, no constraint is violated, no fallback taken."""
    run = runs(**PAPER)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["disturbances"] == ["T_in"] and info["fallbacks"] == 0
    assert info["disturbance_refusals"] == 0
    assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
    df = run.to_pandas().set_index("time")
    P, T = df["ctrl.P"], df["plant.T"]
    # ambient 20 -> 10 degC at 3000 s, 10 -> 30 at 5000 s: the power moves the right way
    # at once, by hundreds of watts within two samples
    assert P[3000.0] > P[2980.0] + 50 and P[3040.0] > P[2980.0] + 400
    assert P[5000.0] < P[4980.0] - 200 and P[5020.0] < P[4980.0] - 800
    assert abs(T[3000.0:3400.0] - 55.0).max() < 1.0 and abs(T[5000.0:5400.0] - 55.0).max() < 1.0
    for t in (2900.0, 4900.0, 6900.0):
        assert abs(T[t] - 55.0) < 0.5, t


def test_the_paper_laws_compiled_step_replays_the_python_controller_with_disturbance(
        heater: dict[str, Path]) -> None:
    """The paper's law's C step fed what the Python controller saw, ambient steps included:
    its inputs, statuses and fallbacks to the bit (:func:`heaters.replay_paper_law`; the
    heater whose power acts late: :mod:`test_dead_time`)."""
    replay_paper_law(heater["model"], dead_time=0)


@pytest.mark.parametrize("options", [{}, PAPER])
def test_a_set_point_the_disturbance_puts_out_of_reach_is_said_in_the_users_names(
        heater: dict[str, Path], tmp_path: Path, options: dict) -> None:
    """60 degC in a 5 degC room needs more than the heater's 2,000 W: either law goes to the
    closest reachable temperature at full power, says so in the problem's names and units,
    and returns to the set-point when the ambient does."""
    import cosim

    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.T,dist.T_in\n0,55,20\n1000,60,20\n2000,60,5\n4000,60,20\n"
                        "5000,,\n")
    run = cosim.run(scenario, plant=heater["fmu"], model=heater["model"], options=options,
                    figure=False)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    said = info["setpoint_rejections"] if options else info["notes"]
    # (the paper's offset-free law names the model's set-point, 60 degC less its offset)
    asked = [float(m.group(1)) for line in said if "at T_in=5 degC" in line
             and "closest reachable" in line for m in [re.search(r"set-point T=([\d.]+)", line)]
             if m]
    assert asked and all(abs(v - 60.0) < 0.5 for v in asked), said
    df = run.to_pandas().set_index("time")
    assert df.loc[2400.0:3980.0, "ctrl.P"].min() > 1990.0          # full power meanwhile
    assert abs(df.loc[4980.0, "plant.T"] - 60.0) < 0.5             # and back at 60 degC


def test_the_paper_laws_controller_fmu_takes_the_disturbance_as_the_python_controller(
        heater: dict[str, Path], runs: Any, tmp_path: Path) -> None:
    """``cosim export-fmu --option law="paper"`` of the model with its ambient measured
    (exported for the scenario's set-points, as cosim run designs for them): in closed loop
    with the plant, the Python controller's inputs to the bit."""
    import cosim

    fmu = tmp_path / "Paper.fmu"
    options = [item for k, v in PAPER.items()
               for item in ("--option", f"{k}={json.dumps(v)}")]
    assert main(["export-fmu", str(heater["model"]), *options, "--scenario",
                 str(heater["scenario"]), "--out", str(fmu), "--quiet"]) == 0
    py = runs(**PAPER).to_pandas()
    run = cosim.run(heater["scenario"], plant=heater["fmu"], controller=str(fmu),
                    problem=heater["folder"] / "heater.toml", figure=False).to_pandas()
    np.testing.assert_array_equal(run["ctrl.P"].to_numpy(), py["ctrl.P"].to_numpy())
    assert np.ptp(run["dist.T_in"].to_numpy()) == 20.0


def test_a_scenario_naming_an_unknown_disturbance_is_refused(
        heater: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(SCENARIO.replace("dist.T_in", "dist.T_out"))
    code = main(["run", str(bad), "--plant", str(heater["fmu"]), "--controller", "pi",
                 "--model", str(heater["model"]), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and f"{bad}:1:3: unknown disturbance 'dist.T_out'" in err
    assert "the problem measures dist.T_in" in err and "\n" not in err


def test_without_a_column_the_disturbance_is_nominal(heater: dict[str, Path],
                                                     tmp_path: Path) -> None:
    plain = tmp_path / "plain.csv"
    plain.write_text("time,ref.T\n0,45\n600,45\n")
    out = tmp_path / "o"
    assert main(["run", str(plain), "--plant", str(heater["fmu"]), "--model",
                 str(heater["model"]), "--out", str(out), "--quiet"]) == 0
    assert set(pd.read_csv(out / "results.csv")["dist.T_in"]) == {20.0}


def test_certify_designs_as_the_controller_and_the_fmu_takes_the_disturbance(
        heater: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "gru.json"
    model.write_bytes(heater["model"].read_bytes())
    before = json.loads(model.read_text())
    code = main(["certify", str(model), "--data", str(heater["data"]), "--save"])
    out = capsys.readouterr()
    assert code in (0, 1) and "Traceback" not in out.err and "must be a" not in out.err, out.err
    after = json.loads(model.read_text())
    # the file keeps the full model (inputs and disturbances), with the verdict and gains
    assert [s["name"] for s in after["inputs"]] == ["P", "T_in"]
    assert after["W_z"] == before["W_z"] and "certificate" in after and "observer" in after
    fmu = tmp_path / "c.fmu"   # the disturbance without dead time exports too
    assert main(["export-fmu", str(model), "--out", str(fmu), "--quiet"]) == 0
    import fmpy

    names = {v.name: v.causality for v in fmpy.read_model_description(str(fmu)).modelVariables}
    assert names["dist.T_in"] == "input" and names["P"] == "output"
