"""The robust MPC exported as a controller FMU (``cosim export-fmu``) gives the inputs of the
Python controller component it was exported from, on the four tanks.

Stepped in the project's master (set ``y_k`` and the set-points, controller ``doStep``, read
``u_k``, plant ``doStep``), plant FMU + controller FMU give the same inputs as the Python
``robust-mpc`` to ≤ 1e-9 of each input's box -- measured: to the bit -- on the paper scenario
(FMI 2 and 3), with the same statuses and fallbacks; with a tuned parameter, from a run's
``controller.json``, with the paper's law and in a campaign too. Plants of other kinds:
:mod:`test_controller_export_plants`; the compiled step alone: :mod:`test_compiled_step`.
"""

from __future__ import annotations

import json
from pathlib import Path

import fmpy
import numpy as np
import pytest

import cosim
from cosim.core.errors import CosimError
from tests.cosim.adapters.export_cases import FOUR_TANKS, PAPER, PAPER_LAW, TOL, same_inputs
from tests.toml_text import campaign_spec


@pytest.fixture(scope="module")
def python_paper_run() -> cosim.RunOutput:
    return cosim.run(PAPER, figure=False)


@pytest.mark.parametrize("version", [2, 3])
def test_the_master_runs_the_fmu_as_the_python_controller(
        version: int, controller_fmus: dict[int, Path], python_paper_run: cosim.RunOutput) -> None:
    run = cosim.run(PAPER, controller=str(controller_fmus[version]), figure=False)
    same_inputs(run, python_paper_run, FOUR_TANKS)
    summary = run.summary["controller_summary"]
    assert summary["controller"] == "fmu" and "tracking law, certified" in summary[
        "description"]
    df = run.to_pandas()
    assert {"ctrl.iterations", "ctrl.pred.h1", "ctrl.pred.h2"} <= set(df.columns)
    # the predicted level is the model's: within a few cm of the plant's next one
    err = np.abs(df["ctrl.pred.h1"].to_numpy()[:-1] - df["plant.h1"].to_numpy()[1:])
    assert float(np.median(err)) < 0.02


def test_a_tuned_parameter_is_the_python_option(controller_fmus: dict[int, Path],
                                                tmp_path: Path) -> None:
    """The FMU's tunable ``offset_filter`` set to 0.6 (``--option`` of its component) gives
    the Python controller with ``offset_filter=0.6``; 0, refused by the FMU, is bad input
    (the FMU's reason, the previous run's files kept); an option the FMU has no parameter for
    is named."""
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.3,1.4\n1500,,\n")
    fmu = str(controller_fmus[3])
    py = cosim.run(scenario, options={"offset_filter": 0.6}, figure=False)
    tuned = cosim.run(scenario, controller=fmu, options={"offset_filter": 0.6},
                      out=tmp_path / "tuned", figure=False)
    same_inputs(tuned, py, FOUR_TANKS)
    assert tuned.summary["controller_summary"]["parameters"] == {"offset_filter": 0.6}
    # its controller.json names the FMU (fingerprinted) and the parameter: the same run again
    recorded = json.loads((tmp_path / "tuned" / "controller.json").read_text())
    assert recorded["options"] == {"path": fmu, "offset_filter": 0.6}
    assert "sha256" in recorded["files"]["path"]
    again = cosim.run(scenario, controller=str(tmp_path / "tuned" / "controller.json"),
                      figure=False)
    same_inputs(again, tuned, FOUR_TANKS)
    default = cosim.run(scenario, controller=fmu, figure=False).to_pandas()
    assert not np.array_equal(default["ctrl.qa"], tuned.to_pandas()["ctrl.qa"])
    # refused by the FMU at its start: bad input, nothing runs (and nothing is written)
    with pytest.raises(CosimError, match=r"cannot set offset_filter = 0: must be in \(0, 1\]"):
        cosim.run(scenario, controller=fmu, options={"offset_filter": 0.0},
                  out=tmp_path / "tuned", figure=False)
    assert json.loads((tmp_path / "tuned" / "controller.json").read_text()) == recorded
    with pytest.raises(CosimError, match="'N' is not a parameter of the controller FMU"):
        cosim.run(scenario, controller=fmu, options={"N": 40}, figure=False)


def test_tuned_weights_are_the_python_options(controller_fmus: dict[int, Path],
                                             tmp_path: Path) -> None:
    """The FMU's weights as tunable parameters (``R.<input>``, ``du_weight.<input>``,
    ``offset_weight.<output>``, their start values the design's): set through the robust
    MPC's option form they give the Python controller with those options; a weight that
    would leave R not positive definite (the FMU's reason), or one outside its declared box,
    is bad input."""
    md = fmpy.read_model_description(str(controller_fmus[2]))
    params = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    assert list(params) == ["offset_filter", "R.qa", "R.qb", "du_weight.qa", "du_weight.qb",
                            "offset_weight.h1", "offset_weight.h2"]
    assert all(v.variability == "tunable" for v in params.values())
    assert params["R.qa"].max is None and float(params["offset_weight.h1"].start) == 1e4
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.3,1.4\n1500,,\n")
    options = {"R": {"qa": 0.05}, "du_weight": 0.2, "offset_weight": {"h1": 1e3}}
    py = cosim.run(scenario, options=options, figure=False)
    for version in (2, 3):
        tuned = cosim.run(scenario, controller=str(controller_fmus[version]), options=options,
                          out=tmp_path / f"fmi{version}", figure=False)
        same_inputs(tuned, py, FOUR_TANKS)
    assert tuned.summary["controller_summary"]["parameters"] == {
        "R.qa": 0.05, "du_weight.qa": 0.2, "du_weight.qb": 0.2, "offset_weight.h1": 1e3}
    default = cosim.run(scenario, controller=str(controller_fmus[3]), figure=False).to_pandas()
    assert not np.array_equal(default["ctrl.qa"], tuned.to_pandas()["ctrl.qa"])
    for bad, why in ((("R", 0.0), "must keep R positive definite"),
                     (("du_weight", -1.0), r"du_weight.qa=-1.0: outside its range \[0, inf\]"),
                     (("offset_weight", 0.0), "must be a finite weight > 0")):
        with pytest.raises(CosimError, match=why):   # bad input: nothing runs
            cosim.run(scenario, controller=str(controller_fmus[3]), options=dict([bad]),
                      figure=False)
    with pytest.raises(CosimError, match="'h3' is not one of its signals"):
        cosim.run(scenario, controller=str(controller_fmus[3]),
                  options={"offset_weight": {"h3": 1.0}}, figure=False)


def test_a_runs_controller_json_exports_that_controller(tmp_path: Path) -> None:
    """``cosim export-fmu --controller run/controller.json``: the robust MPC of that run (its
    options: offset_filter 0.5 as the FMU's start value), with the run's inputs."""
    from cosim.cli import main

    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.2,1.3\n1250,,\n")
    py = cosim.run(scenario, options={"offset_filter": 0.5}, out=tmp_path / "run", figure=False)
    fmu = tmp_path / "Mpc.fmu"
    assert main(["export-fmu", "--controller", str(tmp_path / "run" / "controller.json"),
                 "--out", str(fmu), "--quiet"]) == 0
    md = fmpy.read_model_description(str(fmu))
    assert {v.name: v.start for v in md.modelVariables}["offset_filter"] == "0.5"
    same_inputs(cosim.run(scenario, controller=str(fmu), figure=False), py, FOUR_TANKS)
    (tmp_path / "pi.json").write_text('{"format": "gru-mpc-controller/1", "controller": "pi", '
                                      '"options": {}, "files": {}}')
    with pytest.raises(CosimError, match="describes controller 'pi'; only the robust MPC"):
        cosim.export_fmu(controller=tmp_path / "pi.json", out=tmp_path / "P.fmu")


@pytest.mark.parametrize(("version", "isolated"), [(3, False), (3, True), (2, True)],
                         ids=["fmi3-in-process", "fmi3-worker", "fmi2-worker"])
def test_samples_the_master_skips_hold_the_fmu_as_the_python_controller(
        version: int, isolated: bool, controller_fmus: dict[int, Path]) -> None:
    """A live run does not step its controller at a sample without a fresh measurement; an
    FMU's clock cannot skip it: the skipped samples are stepped with the measured outputs
    not finite, which holds the exported controller as the Python controller that was not
    stepped (the same inputs after each gap; before, the FMU refused the next doStep)."""
    from cosim.adapters.robust_mpc import RobustMPCController
    from cosim.core.fmu_controller import FmuController
    from cosim.core.isolated import IsolatedFmuController

    fmu = (IsolatedFmuController if isolated else FmuController)(controller_fmus[version])
    py = RobustMPCController()
    fmu.setup(0.0)
    py.setup(0.0)
    rng = np.random.default_rng(7)
    y = np.array([0.62, 0.71])
    boxes = {"qa": 9.05e-4, "qb": 1.11e-3}
    stepped = 0
    try:
        for k in range(40):
            y = y + rng.normal(0.0, 2e-3, 2)
            if 10 <= k < 14 or k == 20:      # no fresh measurement: not stepped
                continue
            values = {"h1": y[0], "h2": y[1], "ref.h1": 0.65 if k < 25 else 0.9,
                      "ref.h2": 0.65}
            for c in (fmu, py):
                c.set_inputs(values)
                c.step(25.0 * k, 25.0)
            a, b = fmu.get_outputs(), py.get_outputs()
            for name, box in boxes.items():
                assert abs(a[name] - b[name]) <= TOL * box, (k, name, a[name], b[name])
            stepped += 1
    finally:
        fmu.terminate()
    assert stepped == 35


@pytest.mark.parametrize("law", [PAPER_LAW, {"law": "paper"}], ids=["paper", "governor"])
def test_the_paper_law_exported_runs_as_the_python_law(law: dict, tmp_path: Path) -> None:
    """``cosim export-fmu --option law=\"paper\" --option governor=false`` (the paper's
    controller) and ``--option law=\"paper\"`` (with its reference governor): on the paper
    scenario, through its failed solves and fallbacks after the set-point steps, the FMU
    gives the Python law's inputs, statuses and fallbacks (to the bit here); its tunable
    parameters are R's diagonal (no offset filter without ``offset_free``, no offset
    weight), and R tuned gives the Python law with that R. Its outputs ``target.<output>``
    are the FHOCP's set-point: with the governor, short of the request after a step."""
    fmu = cosim.export_fmu(out=tmp_path / "Paper.fmu", options=law)
    md = fmpy.read_model_description(str(fmu))
    assert "paper's law, certified" in md.description
    assert [v.name for v in md.modelVariables if v.causality == "parameter"] == ["R.qa", "R.qb"]
    boxes = FOUR_TANKS
    py = cosim.run(PAPER, options=law, figure=False)
    if law.get("governor", True):
        assert py.summary["controller_summary"]["governor_steps"] > 0
    else:
        assert set(py.to_pandas()["ctrl.fallback"]) == {0.0, 1.0}
    run = cosim.run(PAPER, controller=str(fmu), figure=False)
    same_inputs(run, py, boxes)
    df = run.to_pandas()   # the governed set-point short of the request after a step: seen
    assert bool((df["ctrl.target.h1"] != df["ref.h1"]).any()) is law.get("governor", True)
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,0.8,0.9\n1000,,\n")
    tuned = {"R": {"qa": 0.05}}
    same_inputs(cosim.run(scenario, controller=str(fmu), options=tuned, figure=False),
                cosim.run(scenario, options={**law, **tuned}, figure=False), boxes)


def test_a_tuned_setpoint_rate_is_the_python_option(tmp_path: Path) -> None:
    """The paper's law designed with a set-point rate has it as a tunable parameter
    ``setpoint_rate`` (each output's units per sample): tuned to 0.02 m the FMU gives the
    Python law with ``setpoint_rate=0.02``; 0 is refused by the FMU, one line (bad input)."""
    law = {"law": "paper", "setpoint_rate": 0.05}
    fmu = cosim.export_fmu(out=tmp_path / "Rate.fmu", options=law)
    md = fmpy.read_model_description(str(fmu))
    rate = {v.name: v for v in md.modelVariables}["setpoint_rate"]
    assert rate.causality == "parameter" and float(rate.start) == 0.05
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.3,1.4\n1500,,\n")
    tuned = cosim.run(scenario, controller=str(fmu), options={"setpoint_rate": 0.02},
                      figure=False)
    same_inputs(tuned, cosim.run(scenario, options={**law, "setpoint_rate": 0.02},
                                 figure=False), FOUR_TANKS)
    with pytest.raises(CosimError, match="cannot set setpoint_rate = 0: must be a finite rate"):
        cosim.run(scenario, controller=str(fmu), options={"setpoint_rate": 0.0}, figure=False)


def test_a_campaign_qualifies_the_fmu_on_the_python_controllers_draws(
        controller_fmus: dict[int, Path], tmp_path: Path) -> None:
    """A campaign variant ``controller = "Mpc.fmu"`` (packed with the campaign, found beside
    the spec) runs on a Dask worker on the draws of the Python variant: plant uncertainty and
    sensor noise, the same inputs and levels run by run."""
    (tmp_path / "Mpc.fmu").write_bytes(controller_fmus[3].read_bytes())
    spec = campaign_spec(tmp_path, name="fmu-vs-python", runs=2, seed=7, scenario=PAPER,
                         controller="robust-mpc",
                         draw={"plant.a1": {"uniform": [1.2445e-4, 1.3755e-4]},
                               "plant.gamma_a": {"uniform": [0.27, 0.33]},
                               "sensor.h1.noise": {"uniform": [0.0, 0.005]}},
                         tables={"setpoints": {"count": 2, "hold": 500}},
                         variants=[{"name": "python"}, {"name": "fmu", "controller": "Mpc.fmu"}])
    import pandas as pd

    result = cosim.run_campaign(spec, tmp_path / "out", workers=1)
    assert result.status == "ok"
    for run in range(2):
        py, fmu = (pd.read_csv(tmp_path / "out" / "runs" / f"{run:06d}-{v}" / "results.csv")
                   for v in ("python", "fmu"))
        for column in ("ctrl.qa", "ctrl.qb", "plant.h1", "plant.h2"):
            np.testing.assert_array_equal(fmu[column], py[column])

    spec.write_text(spec.read_text().replace('"Mpc.fmu"', '"Nope.fmu"'))
    with pytest.raises(CosimError, match=r"spec.toml:\d+.*'Nope.fmu': controller FMU not "
                                         "found"):
        cosim.run_campaign(spec, tmp_path / "out2", workers=1)


def test_a_tuned_models_weights_are_the_fmus(tmp_path: Path) -> None:
    """A model whose problem carries ``[mpc]`` weights (``cosim tune --save`` writes them)
    exports the controller with those weights: its FMU gives the tuned Python controller's
    inputs, not the default one's."""
    from controllers.model import DEFAULT_MODEL

    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    doc["problem"]["mpc"] = {"Q": "outputs", "R": 0.001, "du_weight": 0.01}
    model = tmp_path / "tuned.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.2,1.3\n1250,,\n")
    fmu = cosim.export_fmu(model=model, out=tmp_path / "Tuned.fmu")
    py = cosim.run(scenario, model=model, figure=False)
    assert py.summary["controller_summary"]["options"]["Q"] == "outputs"
    same_inputs(cosim.run(scenario, controller=str(fmu), figure=False), py, FOUR_TANKS)
    default = cosim.run(scenario, figure=False).to_pandas()
    assert not np.array_equal(default["ctrl.qa"], py.to_pandas()["ctrl.qa"])
