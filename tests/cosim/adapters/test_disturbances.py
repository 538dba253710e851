"""Measured disturbances and dead time through the workflow, on the example heater with its
ambient temperature measured (a tunable parameter of the FMU): ``generate-data`` excites it and
logs its column, ``train`` makes it a model input and says what measuring it is worth, a
scenario's ``dist.T_in`` sets it on the plant and is recorded, the PI adds its static
feedforward, and the robust MPC (tracking law, compiled kernel and numpy alike) holds it over
its horizon; on the heater whose power acts two samples late (``heater_dead_time``) the MPC
predicts over the dead time and beats the PI without overshoot."""

from __future__ import annotations

import csv
import itertools
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.cli import main
from cosim.core.errors import CosimError
from tests import example_builds
from tests.heater_problem import HEATER

ROOT = Path(__file__).resolve().parents[3]
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
    data, model = folder / "data.csv", folder / "gru.json"
    assert main(["generate-data", "--plant", str(fmu), "--problem", str(folder / "heater.toml"),
                 "--steps", "3000", "--out", str(data), "--quiet"]) == 0
    assert main(["train", str(data), "--epochs", "40", "--n", "6", "--out", str(model),
                 "--quiet"]) == 0
    return {"fmu": fmu, "folder": folder, "data": data, "model": model,
            "scenario": folder / "steps.csv"}


def _rows(path: Path) -> list[dict[str, float]]:
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def _iae(rows: list[dict[str, float]], start: float, end: float) -> float:
    return sum(abs(r["ref.T"] - r["plant.T"]) * 20.0 for r in rows if start <= r["time"] < end)


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
        runs[ff] = _rows(out / "results.csv")
        summary = json.loads((out / "summary.json").read_text())["controller_summary"]
        assert (summary["feedforward"] is not None) is (ff == "true")
    with_ff, without = runs["true"], runs["false"]
    assert [r["dist.T_in"] for r in with_ff][::50] == [20.0] * 3 + [10.0] * 2 + [30.0] * 3
    # the ambient moves the plant: at the same set-point the PI needs more power when colder
    at = {r["time"]: r for r in without}
    assert at[2980.0]["ctrl.P"] < at[4980.0]["ctrl.P"] > at[6980.0]["ctrl.P"]
    # the feedforward rejects the ambient steps far better, the set-point step alike
    for start, end in ((3000, 5000), (5000, 7001)):
        assert _iae(with_ff, start, end) < 0.5 * _iae(without, start, end)
    assert _iae(with_ff, 0, 3000) == pytest.approx(_iae(without, 0, 3000), rel=1e-9)


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
        results[kernel] = _rows(out / "results.csv")
    compiled, numpy_ = results["auto"], results["numpy"]
    # the kernel's SQP and casadi's on the numpy derivatives: the same closed loop, nearly
    assert _iae(compiled, 0, 7001) == pytest.approx(_iae(numpy_, 0, 7001), rel=0.1)
    # it reacts to the ambient at once (feedforward): more power the step it gets colder
    at = {r["time"]: r for r in compiled}
    assert at[3000.0]["ctrl.P"] > at[2980.0]["ctrl.P"] + 100.0
    assert at[5000.0]["ctrl.P"] < at[4980.0]["ctrl.P"] - 100.0
    # and tracks the set-point after each step
    for t in (2980.0, 4980.0, 6980.0):
        assert abs(at[t]["plant.T"] - 55.0) < 0.5, t


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


def _replay(ctrl: Any, compiled: Any, steps: int, ref: Callable[[int], float],
            dist: Callable[[int], float]) -> None:
    """Step the Python controller ``ctrl`` and the exported C step ``compiled`` on the same
    measurements (a first-order response to the set-point ``ref(k)`` with sensor noise, the
    ambient ``dist(k)``): the same inputs, statuses, fallbacks and targets, to the bit."""
    ctrl.setup(0.0)
    rng = np.random.default_rng(3)
    y = 45.0
    for k in range(steps):
        r, d = ref(k), dist(k)
        y = y + 0.3 * (r - y) * 0.2 + rng.normal(0.0, 0.05)
        ctrl.set_inputs({"T": y, "ref.T": r, "dist.T_in": d})
        ctrl.step(20.0 * k, 20.0)
        out = compiled.step(np.array([y]), np.array([r]), np.array([d]))
        np.testing.assert_array_equal(out["u"], [ctrl.get_outputs()["P"]])
        diag = ctrl.diagnostics()
        assert (out["status"], out["fallback"]) == (diag["status"], diag["fallback"]), k
        np.testing.assert_array_equal(out["y_target"], [diag["y_model_T"]])
    compiled.close()


#: the paper's law with a horizon for the heater's time constants (its default N = 15 is the
#: four tanks'), the offset-free set-point
PAPER = {"law": "paper", "N": 60, "offset_free": True}


def test_the_paper_law_holds_the_measured_disturbance(heater: dict[str, Path]) -> None:
    """The paper's law computes its reference (x_bar, u_bar) again when the measured ambient
    moves: its power follows at once (the model's static feedforward), the set-point is held
    through both ambient steps, no constraint is violated, no fallback taken."""
    import cosim

    run = cosim.run(heater["scenario"], plant=heater["fmu"], model=heater["model"],
                    options=PAPER, figure=False)
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


@pytest.mark.parametrize("plant", ["heater", "dead_time"])
def test_the_paper_laws_compiled_step_replays_the_python_controller_with_disturbance(
        plant: str, request: pytest.FixtureRequest) -> None:
    """The paper's law's C step (governor, offset-free set-point) fed what the Python
    controller saw, ambient steps included, one of which leaves the set-point unreachable
    (the last reference kept, said in the user's names): its inputs, statuses and fallbacks
    to the bit, step by step; on the heater whose power acts two samples late, its FHOCP
    and governor start from the estimate predicted over the dead time, alike."""
    heater = request.getfixturevalue(plant)
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=heater["model"], **PAPER)
    ctrl.expect_setpoints([{"T": 45.0}, {"T": 55.0}, {"T": 60.0}])   # uncertified for them
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    assert design.q == 1 and design.dead_time == (2 if plant == "dead_time" else 0)
    compiled = CompiledController(*build(design), design_data(design), n_inputs=1,
                                  n_outputs=1, n_disturbances=1)
    _replay(ctrl, compiled, 160, lambda k: 45.0 if k < 20 else 55.0 if k < 70 else 60.0,
            lambda k: 20.0 if k < 40 else 10.0 if k < 90 else 30.0 if k < 120 else 5.0)
    info = ctrl.mpc.law.summary()
    assert info["disturbance_refusals"] >= 1
    assert any("is not reachable at T_in=5 degC: the closest reachable output" in r
               for r in info["setpoint_rejections"]), info["setpoint_rejections"]


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
    assert any("at T_in=5 degC" in line and "T=60" in line and "closest reachable" in line
               for line in said), said
    df = run.to_pandas().set_index("time")
    assert df.loc[2400.0:4000.0, "ctrl.P"].min() > 1990.0          # full power meanwhile
    assert abs(df.loc[4980.0, "plant.T"] - 60.0) < 0.5             # and back at 60 degC


def test_the_paper_laws_controller_fmu_takes_the_disturbance_as_the_python_controller(
        heater: dict[str, Path], tmp_path: Path) -> None:
    """``cosim export-fmu --option law="paper"`` of the model with its ambient measured
    (exported for the scenario's set-points, as cosim run designs for them): in closed loop
    with the plant, the Python controller's inputs to the bit."""
    import cosim

    fmu = tmp_path / "Paper.fmu"
    options = [item for k, v in PAPER.items()
               for item in ("--option", f"{k}={json.dumps(v)}")]
    assert main(["export-fmu", str(heater["model"]), *options, "--scenario",
                 str(heater["scenario"]), "--out", str(fmu), "--quiet"]) == 0
    py = cosim.run(heater["scenario"], plant=heater["fmu"], model=heater["model"],
                   options=PAPER, figure=False).to_pandas()
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
    assert {r["dist.T_in"] for r in _rows(out / "results.csv")} == {20.0}


DEAD_TIME_SCENARIO = ("time,ref.T,dist.T_in\n0,40,20\n1000,55,20\n3000,55,15\n5000,55,25\n"
                      "7000,55,25\n")


@pytest.fixture(scope="module")
def dead_time(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The heater whose power acts 40 s (two samples) late, data and a brief model."""
    folder = tmp_path_factory.mktemp("heater_dt")
    fmu = example_builds.build("heater_dead_time", folder)
    problem = example_builds.problem_file("heater_dead_time")
    data, model = folder / "data.csv", folder / "gru.json"
    assert main(["generate-data", "--plant", str(fmu), "--problem", str(problem), "--steps",
                 "4000", "--out", str(data), "--quiet"]) == 0
    assert main(["train", str(data), "--epochs", "60", "--n", "6", "--out", str(model),
                 "--quiet"]) == 0
    (folder / "steps.csv").write_text(DEAD_TIME_SCENARIO)
    return {"fmu": fmu, "model": model, "scenario": folder / "steps.csv"}


def test_the_paper_law_predicts_over_the_dead_time(dead_time: dict[str, Path]) -> None:
    """The paper's law on the heater whose power acts two samples late: no violation, no
    fallback, the set-point step without overshoot beyond 2 %, the set-point held through
    the ambient steps."""
    import cosim

    run = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], model=dead_time["model"],
                    options=PAPER, figure=False)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["dead_time"] == 2 and info["fallbacks"] == 0
    assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
    T = run.to_pandas().set_index("time")["plant.T"]
    assert T[1000.0:3000.0].max() < 55.0 + 0.02 * 15.0
    assert abs(T[2980.0] - 55.0) < 0.3 and abs(T[6980.0] - 55.0) < 0.3


def _previewed(model: Path, folder: Path) -> Path:
    """``model`` with its disturbance declared known ahead (``preview = true``)."""
    doc = json.loads(model.read_text())
    for entry in doc["problem"]["disturbances"]:
        entry["preview"] = True
    path = folder / "gru_preview.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("options", [{}, PAPER], ids=["tracking", "paper"])
def test_a_disturbance_known_ahead_is_met_before_it_arrives(
        dead_time: dict[str, Path], tmp_path: Path, options: dict) -> None:
    """``preview = true`` on the ambient of the heater whose power acts two samples late:
    the scenario's ambient steps are known over the dead time, so the power moves two
    samples before each arrives and the temperature stays closer to its set-point than
    with the ambient only measured (at most 0.8x the IAE of each step; measured: 0.36x and
    0.36x tracking, 0.72x and 0.72x the paper's law), the set-point step unchanged, 0
    violations, 0 fallbacks."""
    import cosim

    runs = {}
    for name, model in (("held", dead_time["model"]),
                        ("preview", _previewed(dead_time["model"], tmp_path))):
        run = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], model=model,
                        options=options, figure=False)
        assert run.status == "ok", run.reason
        info = run.summary["controller_summary"]
        assert info["fallbacks"] == 0
        assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
        runs[name] = run.to_pandas().set_index("time")
        if name == "preview":
            assert info["previewed"] == ["T_in"] and info["preview_held_steps"] == 0

    def iae(df: Any, start: float, end: float) -> float:
        return float((df["plant.T"] - df["ref.T"])[start:end - 1.0].abs().sum() * 20.0)

    held, ahead = runs["held"], runs["preview"]
    for start, end in ((3000.0, 5000.0), (5000.0, 7000.0)):
        assert iae(ahead, start, end) <= 0.8 * iae(held, start, end), (start, end)
    assert iae(ahead, 1000.0, 3000.0) <= 1.01 * iae(held, 1000.0, 3000.0)
    # the ambient falls 20 -> 15 degC at 3000 s: the power rises to its new level at
    # 2960 s (two samples ahead: measured, +270 W), the measured-only controller's at 3000 s
    assert ahead["ctrl.P"][2960.0] > ahead["ctrl.P"][2940.0] + 200.0
    assert held["ctrl.P"][2960.0] < held["ctrl.P"][2940.0] + 50.0


def test_isolated_a_disturbance_known_ahead_is_told_as_in_process(
        dead_time: dict[str, Path], tmp_path: Path) -> None:
    """``--isolate`` runs the controller in a worker: the scenario's schedule (PREVIEW, a
    declared capability) travels to it as data, and the run is the in-process run to the
    bit (before, the proxy told its local copy and the worker held the ambient)."""
    import cosim

    model = _previewed(dead_time["model"], tmp_path)
    runs = [cosim.run(dead_time["scenario"], plant=dead_time["fmu"], model=model,
                      isolate=isolate, figure=False) for isolate in (False, True)]
    for run in runs:
        assert run.status == "ok", run.reason
        assert run.summary["controller_summary"]["preview_held_steps"] == 0
    assert runs[0].result.columns == runs[1].result.columns
    assert runs[0].result.rows == runs[1].result.rows


def test_without_a_schedule_a_disturbance_known_ahead_is_held(
        dead_time: dict[str, Path], tmp_path: Path) -> None:
    """Stepped outside a scenario (no schedule: a host stepping it), or in a run whose
    scenario does not set it, the controller of a disturbance known ahead holds its measured
    value, as the one that only measures it: the same inputs to the bit, the steps counted."""
    from cosim.adapters.robust_mpc import RobustMPCController

    held = RobustMPCController(model=dead_time["model"])
    ahead = RobustMPCController(model=_previewed(dead_time["model"], tmp_path))
    assert ahead.previewed == ("T_in",) and held.previewed == ()
    for ctrl in (held, ahead):
        ctrl.setup(0.0)
    for k in range(40):
        values = {"T": 40.0 + 0.1 * k, "ref.T": 45.0, "dist.T_in": 20.0 if k < 20 else 12.0}
        for ctrl in (held, ahead):
            ctrl.set_inputs(values)
            ctrl.step(20.0 * k, 20.0)
        assert held.get_outputs() == ahead.get_outputs(), k
    assert ahead.summary()["preview_held_steps"] == 40
    # a scenario that does not set it (the plant's own, a live plant's measured) tells nothing
    import cosim

    plain = tmp_path / "plain.csv"
    plain.write_text("time,ref.T\n0,45\n400,45\n")
    run = cosim.run(plain, plant=dead_time["fmu"], model=_previewed(dead_time["model"],
                                                                    tmp_path), figure=False)
    assert run.summary["controller_summary"]["preview_held_steps"] == 21


def test_a_controller_fmu_is_not_told_what_comes(dead_time: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["export-fmu", str(_previewed(dead_time["model"], tmp_path)), "--out",
                 str(tmp_path / "C.fmu"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    assert "preview = true on T_in: the controller FMU measures its disturbances" in err, err
    assert not (tmp_path / "C.fmu").exists()


def test_the_plants_dead_time_is_two_samples(dead_time: dict[str, Path]) -> None:
    import fmpy

    steps = np.array([(0.0, 1000.0), (99.0, 1000.0), (100.0, 2000.0), (400.0, 2000.0)],
                     dtype=[("time", float), ("P", float)])
    res = fmpy.simulate_fmu(str(dead_time["fmu"]), stop_time=300.0, output_interval=20.0,
                            input=steps)
    T = dict(zip(res["time"].round(6).tolist(), res["T"].tolist(), strict=True))
    assert T[100.0] == T[120.0] == T[140.0] and T[160.0] > T[140.0] + 0.1


def test_the_robust_mpc_predicts_over_the_dead_time(dead_time: dict[str, Path],
                                                    tmp_path: Path) -> None:
    runs = {}
    for name, extra in (("mpc", []), ("pi", ["--controller", "pi"])):
        out = tmp_path / name
        assert main(["run", str(dead_time["scenario"]), "--plant", str(dead_time["fmu"]),
                     "--model", str(dead_time["model"]), *extra, "--out", str(out),
                     "--quiet"]) == 0
        runs[name] = _rows(out / "results.csv")
        if name == "mpc":
            summary = json.loads((out / "summary.json").read_text())
            assert summary["controller_summary"]["dead_time"] == 2
            assert summary["kpis"]["violations"]["T"]["count"] == 0
    mpc, pi = runs["mpc"], runs["pi"]
    # the set-point step 40 -> 55: no overshoot beyond 5 % of the step (the PI's is more)
    step = [r["plant.T"] for r in mpc if 1000 <= r["time"] < 3000]
    assert max(step) < 55.0 + 0.05 * 15.0
    # beats the PI with its feedforward over the whole scenario and on each ambient step
    assert _iae(mpc, 0, 7001) < _iae(pi, 0, 7001)
    for start, end in ((3000, 5000), (5000, 7001)):
        assert _iae(mpc, start, end) < 0.6 * _iae(pi, start, end)


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


def test_a_campaign_draws_disturbance_steps_on_dask(dead_time: dict[str, Path],
                                                    tmp_path: Path) -> None:
    """Two runs of disturbance steps drawn per run, the same for every variant, applied and
    recorded; a variant whose model knows the disturbance ahead is told the drawn steps."""
    problem = ROOT / "fmus" / "examples" / "heater_dead_time" / "problem.toml"
    spec = tmp_path / "spec.toml"
    spec.write_text(
        f'[campaign]\nruns = 2\nseed = 5\nscenario = "{dead_time["scenario"]}"\n'
        f'plant = "{dead_time["fmu"]}"\nmodel = "{dead_time["model"]}"\n'
        f'problem = "{problem}"\n\n[disturbances]\ncount = 3\nhold = 2400\n'
        'T_in = [10.0, 30.0]\n\n[[variant]]\nname = "mpc"\ncontroller = "robust-mpc"\n\n'
        f'[[variant]]\nname = "pi"\ncontroller = "pi"\nmodel = "{dead_time["model"]}"\n\n'
        f'[[variant]]\nname = "ahead"\ncontroller = "robust-mpc"\n'
        f'model = "{_previewed(dead_time["model"], tmp_path)}"\n')
    out = tmp_path / "camp"
    assert main(["campaign", str(spec), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    for run in (0, 1):   # the drawn steps known ahead: the run's scenario is the schedule
        info = json.loads((out / "runs" / f"{run:06d}-ahead" / "summary.json").read_text())[
            "controller_summary"]
        assert info["previewed"] == ["T_in"] and info["preview_held_steps"] == 0
    seen = {}
    for run in (0, 1):
        for variant in ("mpc", "pi"):
            folder = out / "runs" / f"{run:06d}-{variant}"
            steps = json.loads((folder / "summary.json").read_text())[
                "campaign"]["disturbances"]
            rows = _rows(folder / "results.csv")
            for t, levels in steps:   # the plant got them, the results record them
                row = next(r for r in rows if r["time"] >= t)
                assert row["dist.T_in"] == levels["T_in"]
            seen[run, variant] = [levels["T_in"] for _, levels in steps]
    assert seen[0, "mpc"] == seen[0, "pi"] != seen[1, "mpc"] == seen[1, "pi"]


def test_a_campaign_ramps_the_disturbance_at_its_rate(dead_time: dict[str, Path],
                                                      tmp_path: Path) -> None:
    """``[disturbances] ramp = true``: each drawn level is reached at the problem's rate
    (0.5 degC per 20 s sample), one event per sample, and the levels are the steps' own; a
    ramp of a disturbance the model does not measure is refused, naming the spec."""
    from cosim.campaign import draws, spec

    problem = ROOT / "fmus" / "examples" / "heater_dead_time" / "problem.toml"
    text = (f'[campaign]\nruns = 3\nseed = 5\nscenario = "{dead_time["scenario"]}"\n'
            f'plant = "{dead_time["fmu"]}"\nmodel = "{dead_time["model"]}"\n'
            f'problem = "{problem}"\n\n[disturbances]\ncount = 3\nhold = 2400\n'
            'T_in = [10.0, 30.0]\nramp = true\n\n[[variant]]\nname = "mpc"\n'
            'controller = "robust-mpc"\n')
    path = tmp_path / "spec.toml"
    path.write_text(text)
    ramped = spec.load(path)
    (tmp_path / "steps.toml").write_text(text.replace("ramp = true\n", ""))
    stepped = spec.load(tmp_path / "steps.toml")
    ctx = draws.DrawContext.build(ramped, 0.0)
    assert ctx.sample_time == 20.0 and ctx.rates == {"T_in": 0.5}
    for run in range(3):
        events = draws.draw_run(ramped, run, ctx).disturbances
        steps = draws.draw_run(stepped, run, draws.DrawContext.build(stepped, 0.0)).disturbances
        times = [t for t, _ in events]
        values = [v["T_in"] for _, v in events]
        assert events[0] == steps[0] and values[-1] == steps[-1][1]["T_in"]
        starts = {t for t, _ in steps}
        assert all(b - a == 20.0 or b in starts for a, b in itertools.pairwise(times))
        assert np.max(np.abs(np.diff(values))) <= 0.5 + 1e-12 and len(events) > 3
        assert starts <= set(times)   # each ramp starts at its level's time
    path.write_text(text.replace("T_in = [10.0, 30.0]", "T_out = [10.0, 30.0]"))
    with pytest.raises(CosimError, match="'T_out' is not a measured disturbance of the model"):
        draws.DrawContext.build(spec.load(path), 0.0)


def test_the_compiled_step_replays_the_python_controller_with_disturbance_and_dead_time(
        dead_time: dict[str, Path]) -> None:
    """The exported controller's C step fed what the Python controller saw (noisy outputs,
    set-point steps, ambient steps beyond its rate, which move and restart the steady state)
    gives its inputs, statuses and fallbacks to the bit, step by step."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=dead_time["model"])
    design = ctrl.mpc.export_design()
    assert design.q == 1 and design.dead_time == 2
    compiled = CompiledController(*build(design), design_data(design), n_inputs=1,
                                  n_outputs=1, n_disturbances=1)
    _replay(ctrl, compiled, 120, lambda k: 45.0 if k < 20 else 55.0 if k < 70 else 50.0,
            lambda k: 20.0 if k < 40 else 10.0 if k < 90 else 30.0)


def test_the_controller_fmu_takes_the_disturbance_as_the_python_controller(
        dead_time: dict[str, Path], tmp_path: Path) -> None:
    """``cosim export-fmu`` of the model with a measured disturbance and dead time: an input
    ``dist.T_in`` (its box, its middle as start value) and, in closed loop with the plant,
    the Python controller's inputs to the bit."""
    import fmpy

    import cosim

    fmu = tmp_path / "Controller.fmu"
    assert main(["export-fmu", str(dead_time["model"]), "--out", str(fmu), "--quiet"]) == 0
    md = fmpy.read_model_description(str(fmu))
    dist = {v.name: v for v in md.modelVariables}["dist.T_in"]
    assert (dist.causality, float(dist.min), float(dist.max), float(dist.start)) == (
        "input", 5.0, 35.0, 20.0)
    py = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], model=dead_time["model"],
                   figure=False).to_pandas()
    problem = ROOT / "fmus" / "examples" / "heater_dead_time" / "problem.toml"
    run = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], controller=str(fmu),
                    problem=problem, figure=False).to_pandas()   # binds T_in to T_amb
    np.testing.assert_array_equal(run["ctrl.P"].to_numpy(), py["ctrl.P"].to_numpy())
    np.testing.assert_array_equal(run["dist.T_in"].to_numpy(), py["dist.T_in"].to_numpy())
