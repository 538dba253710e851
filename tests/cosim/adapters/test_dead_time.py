"""Measured disturbances on the example heater whose power acts two samples late
(``heater_dead_time``): the robust MPC (either law) predicts over the dead time and beats the
PI without overshoot, a disturbance known ahead (``preview = true``) is met before it arrives,
campaigns draw disturbance steps and ramps, and the exported C step and controller FMU take
the disturbance as the Python controller does."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from cosim.cli import main
from cosim.core.errors import CosimError
from tests import example_builds
from tests.cosim.adapters.heaters import (
    PAPER,
    iae,
    previewed,
    replay,
    replay_paper_law,
    run_cache,
    trained,
)
from tests.toml_text import campaign_spec

PROBLEM = example_builds.problem_file("heater_dead_time")

DEAD_TIME_SCENARIO = ("time,ref.T,dist.T_in\n0,40,20\n1000,55,20\n3000,55,15\n5000,55,25\n"
                      "7000,55,25\n")


@pytest.fixture(scope="module")
def dead_time(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The heater whose power acts 40 s (two samples) late, data, a brief model and the model
    with its disturbance known ahead (``preview``)."""
    folder = tmp_path_factory.mktemp("heater_dt")
    fmu = example_builds.build("heater_dead_time", folder)
    (folder / "steps.csv").write_text(DEAD_TIME_SCENARIO)
    case = {"fmu": fmu, "scenario": folder / "steps.csv",
            **trained(folder, fmu, PROBLEM, steps=4000, epochs=60)}
    return {**case, "preview": previewed(case["model"], folder)}


@pytest.fixture(scope="module")
def runs(dead_time: dict[str, Path]) -> Any:
    """The robust MPC's runs of the scenario, each run once (:func:`run_cache`)."""
    return run_cache(dead_time)


def test_the_paper_law_predicts_over_the_dead_time(runs: Any) -> None:
    """The paper's law on the heater whose power acts two samples late: no violation, no
    fallback, the set-point step without overshoot beyond 2 %, the set-point held through
    the ambient steps."""
    run = runs(**PAPER)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["dead_time"] == 2 and info["fallbacks"] == 0
    assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
    T = run.to_pandas().set_index("time")["plant.T"]
    assert T[1000.0:3000.0].max() < 55.0 + 0.02 * 15.0
    assert abs(T[2980.0] - 55.0) < 0.3 and abs(T[6980.0] - 55.0) < 0.3


@pytest.mark.parametrize("options", [{}, PAPER], ids=["tracking", "paper"])
def test_a_disturbance_known_ahead_is_met_before_it_arrives(runs: Any, options: dict) -> None:
    """``preview = true`` on the ambient of the heater whose power acts two samples late:
    the scenario's ambient steps are known over the dead time, so the power moves two
    samples before each arrives and the temperature stays closer to its set-point than
    with the ambient only measured (at most 0.8x the IAE of each step; measured: 0.36x and
    0.36x tracking, 0.72x and 0.72x the paper's law), the set-point step unchanged, 0
    violations, 0 fallbacks."""
    tables = {}
    for name, model in (("held", "model"), ("preview", "preview")):
        run = runs(model, **options)
        assert run.status == "ok", run.reason
        info = run.summary["controller_summary"]
        assert info["fallbacks"] == 0
        assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
        tables[name] = run.to_pandas()
        if name == "preview":
            assert info["previewed"] == ["T_in"] and info["preview_held_steps"] == 0
    held, ahead = tables["held"], tables["preview"]
    for start, end in ((3000.0, 5000.0), (5000.0, 7000.0)):
        assert iae(ahead, start, end) <= 0.8 * iae(held, start, end), (start, end)
    assert iae(ahead, 1000.0, 3000.0) <= 1.01 * iae(held, 1000.0, 3000.0)
    # the ambient falls 20 -> 15 degC at 3000 s: the power rises to its new level at
    # 2960 s (two samples ahead: measured, +270 W), the measured-only controller's at 3000 s
    P_ahead, P_held = (t.set_index("time")["ctrl.P"] for t in (ahead, held))
    assert P_ahead[2960.0] > P_ahead[2940.0] + 200.0
    assert P_held[2960.0] < P_held[2940.0] + 50.0


def test_isolated_a_disturbance_known_ahead_is_told_as_in_process(
        dead_time: dict[str, Path], runs: Any) -> None:
    """``--isolate`` runs the controller in a worker: the scenario's schedule (PREVIEW, a
    declared capability) travels to it as data, and the run is the in-process run to the
    bit (before, the proxy told its local copy and the worker held the ambient)."""
    import cosim

    isolated = cosim.run(dead_time["scenario"], plant=dead_time["fmu"],
                         model=dead_time["preview"], isolate=True, figure=False)
    in_process = runs("preview")
    for run in (in_process, isolated):
        assert run.status == "ok", run.reason
        assert run.summary["controller_summary"]["preview_held_steps"] == 0
    assert in_process.result.columns == isolated.result.columns
    assert in_process.result.rows == isolated.result.rows


def test_without_a_schedule_a_disturbance_known_ahead_is_held(
        dead_time: dict[str, Path], tmp_path: Path) -> None:
    """Stepped outside a scenario (no schedule: a host stepping it), or in a run whose
    scenario does not set it, the controller of a disturbance known ahead holds its measured
    value, as the one that only measures it: the same inputs to the bit, the steps counted."""
    from cosim.adapters.robust_mpc import RobustMPCController

    held = RobustMPCController(model=dead_time["model"])
    ahead = RobustMPCController(model=dead_time["preview"])
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
    run = cosim.run(plain, plant=dead_time["fmu"], model=dead_time["preview"], figure=False)
    assert run.summary["controller_summary"]["preview_held_steps"] == 21


def test_a_controller_fmu_is_not_told_what_comes(dead_time: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["export-fmu", str(dead_time["preview"]), "--out", str(tmp_path / "C.fmu"),
                 "--quiet"])
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
                                                    runs: Any) -> None:
    import cosim

    run = runs()
    assert run.summary["controller_summary"]["dead_time"] == 2
    assert run.summary["kpis"]["violations"]["T"]["count"] == 0
    mpc = run.to_pandas()
    pi = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], model=dead_time["model"],
                   controller="pi", figure=False).to_pandas()
    # the set-point step 40 -> 55: no overshoot beyond 5 % of the step (the PI's is more)
    step = mpc[(mpc["time"] >= 1000) & (mpc["time"] < 3000)]["plant.T"]
    assert step.max() < 55.0 + 0.05 * 15.0
    # beats the PI with its feedforward over the whole scenario and on each ambient step
    assert iae(mpc, 0, 7001) < iae(pi, 0, 7001)
    for start, end in ((3000, 5000), (5000, 7001)):
        assert iae(mpc, start, end) < 0.6 * iae(pi, start, end)


def _campaign(case: dict[str, Path], path: Path, runs: int, variants: list[dict],
              **disturbances: Any) -> Path:
    """``path``: a campaign of ``runs`` runs of the case's scenario, three steps of the ambient
    drawn per run (``[disturbances]``: ``disturbances`` in place of the defaults, ``None``
    leaving one out). No campaign problem file: each variant's model brings its own (a given
    file would win over the previewing model's)."""
    drawn = {"count": 3, "hold": 2400, "T_in": [10.0, 30.0]} | disturbances
    drawn = {k: v for k, v in drawn.items() if v is not None}
    return campaign_spec(path.parent, file=path.name, runs=runs, seed=5,
                         scenario=case["scenario"], plant=case["fmu"], model=case["model"],
                         tables={"disturbances": drawn}, variants=variants)


def test_a_campaign_draws_disturbance_steps_on_dask(dead_time: dict[str, Path],
                                                    tmp_path: Path) -> None:
    """Two runs of disturbance steps drawn per run, the same for every variant, applied and
    recorded; a variant whose model knows the disturbance ahead is told the drawn steps."""
    spec = _campaign(dead_time, tmp_path / "spec.toml", 2, [
        {"name": "mpc", "controller": "robust-mpc"},
        {"name": "pi", "controller": "pi", "model": dead_time["model"]},
        {"name": "ahead", "controller": "robust-mpc", "model": dead_time["preview"]}])
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
            table = pd.read_csv(folder / "results.csv")
            for t, levels in steps:   # the plant got them, the results record them
                assert table[table["time"] >= t]["dist.T_in"].iloc[0] == levels["T_in"]
            seen[run, variant] = [levels["T_in"] for _, levels in steps]
    assert seen[0, "mpc"] == seen[0, "pi"] != seen[1, "mpc"] == seen[1, "pi"]


def test_a_campaign_ramps_the_disturbance_at_its_rate(dead_time: dict[str, Path],
                                                      tmp_path: Path) -> None:
    """``[disturbances] ramp = true``: each drawn level is reached at the problem's rate
    (0.5 degC per 20 s sample), one event per sample, and the levels are the steps' own; a
    ramp of a disturbance the model does not measure is refused, naming the spec."""
    from cosim.campaign import draws, spec

    mpc = [{"name": "mpc", "controller": "robust-mpc"}]
    ramped = spec.load(_campaign(dead_time, tmp_path / "spec.toml", 3, mpc, ramp=True))
    stepped = spec.load(_campaign(dead_time, tmp_path / "steps.toml", 3, mpc))
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
    bad = _campaign(dead_time, tmp_path / "spec.toml", 3, mpc, ramp=True, T_in=None,
                    T_out=[10.0, 30.0])
    with pytest.raises(CosimError, match="'T_out' is not a measured disturbance of the model"):
        draws.DrawContext.build(spec.load(bad), 0.0)


def test_the_compiled_step_replays_the_python_controller_with_disturbance_and_dead_time(
        dead_time: dict[str, Path]) -> None:
    """The exported controller's C step fed what the Python controller saw (noisy outputs,
    set-point steps, ambient steps beyond its rate, which move and restart the steady state)
    gives its inputs, statuses and fallbacks to the bit, step by step."""
    from controllers.kernel.controller_source import CompiledController, build, design_data
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=dead_time["model"])
    design = ctrl.mpc.export_design()
    assert design.q == 1 and design.dead_time == 2
    compiled = CompiledController(*build(design), design_data(design), n_inputs=1,
                                  n_outputs=1, n_disturbances=1)
    replay(ctrl, compiled, 120, lambda k: 45.0 if k < 20 else 55.0 if k < 70 else 50.0,
           lambda k: 20.0 if k < 40 else 10.0 if k < 90 else 30.0)


def test_the_controller_fmu_takes_the_disturbance_as_the_python_controller(
        dead_time: dict[str, Path], runs: Any, tmp_path: Path) -> None:
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
    py = runs().to_pandas()
    run = cosim.run(dead_time["scenario"], plant=dead_time["fmu"], controller=str(fmu),
                    problem=PROBLEM, figure=False).to_pandas()   # binds T_in to T_amb
    np.testing.assert_array_equal(run["ctrl.P"].to_numpy(), py["ctrl.P"].to_numpy())
    np.testing.assert_array_equal(run["dist.T_in"].to_numpy(), py["dist.T_in"].to_numpy())


def test_the_paper_laws_compiled_step_replays_the_python_controller_with_disturbance(
        dead_time: dict[str, Path]) -> None:
    """The paper's law's C step fed what the Python controller saw, ambient steps included
    (:func:`heaters.replay_paper_law`): its FHOCP and governor start from the estimate
    predicted over the dead time, as the Python law's, to the bit."""
    replay_paper_law(dead_time["model"], dead_time=2)
