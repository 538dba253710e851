"""The robust MPC exported as a controller FMU (``cosim export-fmu``) gives the inputs of the
Python controller component it was exported from.

Stepped in the project's master (set ``y_k`` and the set-points, controller ``doStep``, read
``u_k``, plant ``doStep``), plant FMU + controller FMU give the same inputs as the Python
``robust-mpc`` to ≤ 1e-9 of each input's box -- measured: to the bit -- on the paper scenario
(FMI 2 and 3) and on plants of other kinds (the example CSTR and mixing tank, pythonfmu
FMUs, with GRU models of their problems whose first measured outputs no input in the box
reaches), with the same statuses and fallbacks; with a tuned parameter, from a run's
``controller.json`` and in a campaign too; the compiled step alone (:class:`controllers.kernel.
controller_source.CompiledController`) replays the Python controller's measurements to the
same inputs.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import fmpy
import numpy as np
import pytest

import cosim
from cosim.core.errors import CosimError
from tests.toml_text import campaign_spec

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_steps.csv"
#: The issue's bar: the FMU's inputs within this share of each input's box of the Python
#: controller's (they are equal to the bit on this machine).
TOL = 1e-9
#: The paper's law without its governor (the paper's controller), and with it (its default).
PAPER_LAW = {"law": "paper", "governor": False}
GOVERNED = {"law": "paper", "governor": True}


@pytest.fixture(scope="module")
def python_paper_run() -> cosim.RunOutput:
    return cosim.run(PAPER, figure=False)


def _same_inputs(fmu_run: cosim.RunOutput, py_run: cosim.RunOutput, inputs: dict) -> None:
    a, b = fmu_run.to_pandas(), py_run.to_pandas()
    assert fmu_run.status == py_run.status == "ok"
    assert len(a) == len(b)
    for name, (lo, hi) in inputs.items():
        worst = float(np.max(np.abs(a[f"ctrl.{name}"] - b[f"ctrl.{name}"]))) / (hi - lo)
        assert worst <= TOL, (name, worst)
    np.testing.assert_array_equal(a["ctrl.status"], b["ctrl.status"])
    np.testing.assert_array_equal(a["ctrl.fallback"], b["ctrl.fallback"])
    for name in (c.removeprefix("ctrl.y_model_") for c in b.columns
                 if c.startswith("ctrl.y_model_")):   # the steady output steered to
        np.testing.assert_array_equal(a[f"ctrl.target.{name}"], b[f"ctrl.y_model_{name}"])


@pytest.mark.parametrize("version", [2, 3])
def test_the_master_runs_the_fmu_as_the_python_controller(
        version: int, controller_fmus: dict[int, Path], python_paper_run: cosim.RunOutput) -> None:
    run = cosim.run(PAPER, controller=str(controller_fmus[version]), figure=False)
    _same_inputs(run, python_paper_run, {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
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
    _same_inputs(tuned, py, {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
    assert tuned.summary["controller_summary"]["parameters"] == {"offset_filter": 0.6}
    # its controller.json names the FMU (fingerprinted) and the parameter: the same run again
    recorded = json.loads((tmp_path / "tuned" / "controller.json").read_text())
    assert recorded["options"] == {"path": fmu, "offset_filter": 0.6}
    assert "sha256" in recorded["files"]["path"]
    again = cosim.run(scenario, controller=str(tmp_path / "tuned" / "controller.json"),
                      figure=False)
    _same_inputs(again, tuned, {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
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
        _same_inputs(tuned, py, {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
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
    _same_inputs(cosim.run(scenario, controller=str(fmu), figure=False), py,
                 {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
    (tmp_path / "pi.json").write_text('{"format": "gru-mpc-controller/1", "controller": "pi", '
                                      '"options": {}, "files": {}}')
    with pytest.raises(CosimError, match="describes controller 'pi'; only the robust MPC"):
        cosim.export_fmu(controller=tmp_path / "pi.json", out=tmp_path / "P.fmu")


def _example_case(tmp_path: Path, plant_name: str, seed: int, steps: str
                  ) -> tuple[Path, Path, Path]:
    """An example plant of ``fmus/examples`` (pythonfmu), a GRU model of its problem, and the
    set-point scenario ``steps``."""
    from controllers.problem_file import load
    from tests import example_builds as examples
    from tests.controllers.random_gru import random_gru_model

    plant = examples.build(plant_name, tmp_path / "plants")
    model = random_gru_model(seed, n=10, problem=load(examples.problem_file(plant_name)))
    model.w_y_bar = 0.01
    path = tmp_path / f"{plant_name}_gru.json"
    model.save(path)
    scenario = tmp_path / "steps.csv"
    scenario.write_text(steps)
    return plant, path, scenario


CSTR = {"F": (50.0, 150.0), "Tc": (290.0, 350.0)}


MIXING = {"Fh": (0.3, 1.5), "Fc": (0.3, 1.5), "Fw": (0.3, 1.5)}


FAILS, UNREACHABLE = "failed solves", "an admissible set-point no input reaches"


@pytest.mark.parametrize(("plant_name", "seed", "steps", "boxes", "certified", "reaches",
                          "options"), [
    ("cstr", 3, "time,ref.CA,ref.T\n0,0.5,330\n1500,0.6,320\n3000,0.4,335\n4500,,\n",
     CSTR, True, {FAILS}, {}),
    ("cstr", 3, "time,ref.CA,ref.T\n0,0.5,330\n750,0.995,330\n2250,,\n", CSTR, False, set(),
     {}),
    ("mixing_tank", 4, "time,ref.h,ref.T\n0,1.0,45\n500,1.1,43\n2000,,\n", MIXING, True,
     set(), {}),
    ("cstr", 3, "time,ref.CA,ref.T\n0,0.536,340.4\n1500,0.47,339.9\n3000,0.6,340.8\n"
     "4500,,\n", CSTR, True, set(), PAPER_LAW),
    ("mixing_tank", 4, "time,ref.h,ref.T\n0,1.34,41.66\n500,1.43,44.72\n2000,,\n", MIXING,
     True, set(), PAPER_LAW),
    ("cstr", 3, "time,ref.CA,ref.T\n0,0.536,340.4\n1500,0.6575,321.93\n3000,0.47,339.9\n"
     "4500,0.6,340.8\n6000,,\n", CSTR, True, {UNREACHABLE}, GOVERNED),
    ("mixing_tank", 4, "time,ref.h,ref.T\n0,1.34,41.66\n500,1.43,44.72\n1500,1.2,40\n"
     "2500,,\n", MIXING, True, set(), GOVERNED)],
    ids=["cstr-2x2", "cstr-uncertified", "mixing-tank-3x2", "cstr-2x2-paper",
         "mixing-tank-3x2-paper", "cstr-2x2-paper-governor", "mixing-tank-3x2-paper-governor"])
def test_plants_of_other_kinds(plant_name: str, seed: int, steps: str, boxes: dict,
                               certified: bool, reaches: set[str], options: dict,
                               tmp_path: Path) -> None:
    """The CSTR at Ts = 15 s in L/min, K and mol/L, and the mixing tank with 3 inputs and 2
    outputs at Ts = 10 s, each exported with ``--scenario`` (its set-points checked as
    ``cosim run`` checks them): the FMU's inputs are the Python controller's, through the
    unreachable first outputs (the closest equilibrium), the failed solves of a model far
    from the plant (statuses and fallbacks alike) and, for a set-point outside the certified
    steady outputs, the uncertified mode (the tightening around ``y + d̂``); the paper's law
    on both, from equilibrium outputs of the models, without its governor and with it (the
    mixing tank's: minimum-norm Newton steps), on the CSTR through a set-point the
    certificate admits but no input in the box reaches (refused, the last one kept, as in
    Python)."""
    from cosim.cli import main

    plant, model, steps_csv = _example_case(tmp_path, plant_name, seed, steps)
    fmu = tmp_path / "Controller.fmu"
    flags = [a for k, v in options.items() for a in ("--option", f"{k}={json.dumps(v)}")]
    assert main(["export-fmu", str(model), "--scenario", str(steps_csv), "--out", str(fmu),
                 "--quiet", *flags]) == 0
    description = fmpy.read_model_description(str(fmu)).description
    assert (", certified:" in description) is certified, description
    assert ("paper's law" in description) is bool(options)
    py = cosim.run(steps_csv, plant=plant, model=model, options=options, figure=False)
    summary = py.summary["controller_summary"]
    assert summary["certified"] is certified
    run = cosim.run(steps_csv, plant=plant, controller=str(fmu), figure=False)
    _same_inputs(run, py, boxes)
    if FAILS in reaches:
        assert set(py.to_pandas()["ctrl.status"]) - {0.0}, "the case should reach " + FAILS
    if options == GOVERNED:
        assert summary["governor_steps"] > 0
    rejections = summary.get("setpoint_rejections", [])
    assert any("is not reachable with inputs inside" in r for r in rejections) is (
        UNREACHABLE in reaches), rejections


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


def test_the_compiled_step_replays_the_python_controller() -> None:
    """:class:`CompiledController` fed the measurements the Python controller saw gives its
    inputs, statuses and fallbacks, step by step; a setting changed between two steps
    (:meth:`controllers.mpc.RobustMPC.set`: the weights, ``d̂``'s gain) is the C step's
    tunable parameter of that name: the same inputs to the bit after it, and after a new
    run (the design's settings again)."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
        parameters,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController()
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    names = [p[0] for p in parameters(design, ("qa", "qb"), ("h1", "h2"))]
    assert names == [s[0] for s in ctrl.mpc.settings()]
    changes = {20: {"R.qa": 0.05, "offset_weight.h2": 300.0},
               35: {"offset_filter": 0.6, "du_weight.qb": 0.5}}
    for run in range(2):
        ctrl.setup(0.0)
        compiled.reset()
        refs = [(0.65, 0.65)] * 30 + [(1.3, 1.4)] * 30
        for k, _ in enumerate(_replayed(ctrl, compiled, refs)):
            for name, value in changes.get(k, {}).items() if run == 0 else ():
                assert compiled.set_parameter(names.index(name), value) is None
                assert ctrl.set(name, value).startswith(f"{name} = {value:g}: ")
        assert dict((s[0], s[4]) for s in ctrl.mpc.settings())["R.qa"] == (
            0.05 if run == 0 else 0.01)
    with pytest.raises(CosimError, match=r"setting R\.qa=-1\.0: must keep R positive definite"):
        ctrl.set("R.qa", -1.0)
    assert compiled.set_parameter(names.index("R.qa"), -1.0) is not None
    with pytest.raises(CosimError, match=r"no setting 'R\.zz'"):
        ctrl.set("R.zz", 1.0)
    compiled.close()


def _replayed(ctrl: object, compiled: object, refs: list[tuple[float, float]],
              y0: tuple[float, float] = (0.62, 0.71)) -> Iterator[dict]:
    """Step a Python controller ``ctrl`` of the four-tank's outputs and its compiled step on
    the same noisy measurements (a random walk from ``y0``) with the set-points ``refs`` (one
    per step): the same inputs (to the bit), statuses and fallbacks at every step; yields the
    compiled step's outputs."""
    rng = np.random.default_rng(5)
    y = np.array(y0, dtype=float)
    inputs = ctrl.problem.input_names
    for k, ref in enumerate(np.array(refs, dtype=float)):
        y = y + rng.normal(0.0, 2e-3, 2)
        ctrl.set_inputs({"h1": y[0], "h2": y[1], "ref.h1": ref[0], "ref.h2": ref[1]})
        ctrl.step(25.0 * k, 25.0)
        out = compiled.step(y, ref)
        u = np.array([ctrl.get_outputs()[n] for n in inputs])
        np.testing.assert_array_equal(out["u"], u)
        diag = ctrl.diagnostics()
        assert out["status"] == diag["status"]
        assert out["fallback"] == diag["fallback"]
        np.testing.assert_array_equal(out["y_target"], [diag["y_model_h1"], diag["y_model_h2"]])
        yield out


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
    boxes = {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)}
    py = cosim.run(PAPER, options=law, figure=False)
    if law.get("governor", True):
        assert py.summary["controller_summary"]["governor_steps"] > 0
    else:
        assert set(py.to_pandas()["ctrl.fallback"]) == {0.0, 1.0}
    run = cosim.run(PAPER, controller=str(fmu), figure=False)
    _same_inputs(run, py, boxes)
    df = run.to_pandas()   # the governed set-point short of the request after a step: seen
    assert bool((df["ctrl.target.h1"] != df["ref.h1"]).any()) is law.get("governor", True)
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,0.8,0.9\n1000,,\n")
    tuned = {"R": {"qa": 0.05}}
    _same_inputs(cosim.run(scenario, controller=str(fmu), options=tuned, figure=False),
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
    _same_inputs(tuned, cosim.run(scenario, options={**law, "setpoint_rate": 0.02},
                                  figure=False), {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)})
    with pytest.raises(CosimError, match="cannot set setpoint_rate = 0: must be a finite rate"):
        cosim.run(scenario, controller=str(fmu), options={"setpoint_rate": 0.0}, figure=False)


@pytest.mark.parametrize(("options", "refs", "first_outside", "named"), [
    ({}, ((0.65, 0.65), (1.3, 1.4), (3.0, 0.3)), False, 1),
    ({"offset_free": True, "setpoint_rate": 0.05, "du_weight": 0.1},
     ((0.65, 0.65), (0.9, 1.0), (3.0, 0.3)), False, 0),
    ({}, ((3.0, 0.3), (0.8, 0.9), (0.7, 0.8)), True, 1),
    (GOVERNED, ((0.65, 0.65), (1.3, 1.4), (0.5, 0.6), (3.0, 0.3), (1.0, 1.2)), False, 1),
    ({**GOVERNED, "offset_free": True, "setpoint_rate": 0.05, "du_weight": 0.1},
     ((0.65, 0.65), (1.3, 1.4), (0.5, 0.6), (1.9, 0.2), (1.0, 1.2)), False, 0),
    (GOVERNED, ((3.0, 0.3), (0.8, 0.9), (0.3, 0.4)), True, 1)],
    ids=["paper", "offset-free-rate-limited", "uncertified-first-outside", "governor",
         "governor-offset-free-rate-limited", "governor-uncertified-first-outside"])
def test_the_compiled_paper_step_replays_the_python_law(options: dict, refs: tuple,
                                                        first_outside: bool,
                                                        named: int) -> None:
    """The paper's law in C (``law_paper.c``) fed the measurements the Python law saw:
    its inputs, statuses and fallbacks step by step (to the bit), through set-point steps,
    the offset-free shift and the rate limit, a set-point outside the theory (refused, the
    last admissible one kept: one warning per refused request, where the Python law names
    one; rate-limited, the set-point stops at the boundary, refused step by step, unnamed,
    as in Python) and, uncertified, a first set-point outside (the closest admissible
    one); with the reference governor (``governor=true``, the Python law's default) through
    its moves by fractions of the step, ``λ_max`` halved after failed solves and grown
    again, and its holds."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
        parameters,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(**{**PAPER_LAW, **options})
    if first_outside:
        ctrl.expect_setpoints([{"h1": 3.0, "h2": 0.3}])
        assert not ctrl.mpc.law.certified
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    names = [p[0] for p in parameters(design, ("qa", "qb"), ("h1", "h2"))]
    assert names == (["offset_filter"] if "offset_free" in options else []) + [
        "R.qa", "R.qb"] + (["du_weight.qa", "du_weight.qb"] if "du_weight" in options else []
                           ) + (["setpoint_rate"] if "setpoint_rate" in options else [])
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    refused, fractions = 0, set()
    for k, out in enumerate(_replayed(ctrl, compiled, [r for r in refs for _ in range(25)])):
        assert bool(out["warnings"] & 4) == (len(ctrl.mpc.law.rejections) > refused), k
        refused = len(ctrl.mpc.law.rejections)
        fractions.add(ctrl.mpc.law.lam)
    assert refused == named
    assert ctrl.mpc.law.rejected > 0
    if "governor" in options and not first_outside:   # it moved by fractions of the step
        assert ctrl.mpc.law.governed_steps > 0 and min(fractions - {0.0}) < 0.5, fractions
    compiled.close()


def test_the_compiled_governor_moves_along_the_surface_of_equilibrium_outputs(
        tmp_path: Path) -> None:
    """One input, two outputs: the reachable set-points are a curve, and the governor moves
    along it (the equilibrium outputs of ``ū(v) + λ (ū(r) − ū(v))``), by fractions of the
    step here (N = 5); a set-point off the curve is refused as unreachable. The compiled
    step gives the Python law's inputs, statuses and fallbacks, to the bit, and so does the
    FMU in closed loop with the model as the plant."""
    from controllers.equilibrium import equilibrium_output
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
    )
    from cosim.adapters.robust_mpc import RobustMPCController
    from tests.controllers.random_gru import random_gru_model

    model = random_gru_model(7, n=8, m=1, p=2)
    model.w_y_bar = 0.002
    model.save(tmp_path / "gru_1x2.json")
    x0, v = equilibrium_output(model.params, np.full(1, -0.9))
    _, r = equilibrium_output(model.params, np.full(1, 0.9), x0)
    v, r = model.denormalize_y(v), model.denormalize_y(r)
    ctrl = RobustMPCController(model=tmp_path / "gru_1x2.json", law="paper", N=5)
    ctrl.expect_setpoints([{"h1": a[0], "h2": a[1]} for a in (v, r)])
    assert ctrl.mpc.law.certified
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), n_inputs=1,
                                  n_outputs=2)
    refs = [tuple(v)] * 20 + [tuple(r)] * 40 + [tuple((v + r) / 2)] * 10 + [tuple(v)] * 30
    fractions = {ctrl.mpc.law.lam for _ in _replayed(ctrl, compiled, refs)}
    compiled.close()
    assert min(fractions - {0.0}) < 0.5 and ctrl.mpc.law.governed_steps > 10, fractions
    assert len(ctrl.mpc.law.rejections) == 1 and "is not reachable" in ctrl.mpc.law.rejections[0]
    # the FMU of one input, in closed loop with the model as the plant: the Python law's
    steps = tmp_path / "steps.csv"
    steps.write_text("time,ref.h1,ref.h2\n" + "".join(
        f"{t},{float(a[0])!r},{float(a[1])!r}\n" for t, a in ((0, v), (500, r), (1500, v)))
        + "2500,,\n")
    plant, options = f"model:{tmp_path / 'gru_1x2.json'}", {"law": "paper", "N": 5}
    fmu = cosim.export_fmu(tmp_path / "gru_1x2.json", out=tmp_path / "C.fmu", options=options,
                           scenario=steps)
    py = cosim.run(steps, plant=plant, model=tmp_path / "gru_1x2.json", options=options,
                   figure=False)
    _same_inputs(cosim.run(steps, plant=plant, controller=str(fmu), figure=False), py,
                 {"qa": (0.0, 9.05e-4)})
    assert min(set(py.to_pandas()["ctrl.governor_lambda"]) - {0.0}) < 0.5


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


def _instantiate(unzipped: Path, logger: list[str]) -> object:
    """Instantiate the controller FMU extracted in ``unzipped`` (FMI 2 or 3), logging into
    ``logger``; the fmpy slave."""
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    from tests.fmus.fourtank_run import Plant

    plant = Plant.__new__(Plant)
    plant.md = fmpy.read_model_description(str(unzipped / "modelDescription.xml"))
    plant.version = int(plant.md.fmiVersion[0])
    token = plant.md.guid if plant.version == 2 else plant.md.instantiationToken
    cls = FMU2Slave if plant.version == 2 else FMU3Slave
    plant.fmu = cls(guid=token, unzipDirectory=str(unzipped), instanceName="mpc",
                    modelIdentifier=plant.md.coSimulation.modelIdentifier)
    plant._instantiate(lambda status, category, message: logger.append(message))
    return plant.fmu


def _flipped(data: bytes, at: int) -> bytes:
    """``data`` with one bit of byte ``at`` flipped (a damaged file)."""
    out = bytearray(data)
    out[at] ^= 0x10
    return bytes(out)


def _edited(data: bytes, index: int, value: float) -> bytes:
    """The data file ``data`` with value ``index`` (negative: from the end) set to ``value``
    and its checksum made to match (an edited file)."""
    import struct
    import zlib

    from controllers.kernel.constants import HEADER

    out = bytearray(data)
    (count,) = struct.unpack("<Q", out[24:32])
    at = len(out) - 8 * count + 8 * (index % count)
    out[at:at + 8] = struct.pack("<d", value)
    out[32:HEADER] = struct.pack("<Q", zlib.crc32(bytes(out[HEADER:])))
    return bytes(out)


def test_one_binary_serves_every_model_of_its_dimensions(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Two GRU models of the CSTR (other weights, the same dimensions) exported in turn
    through a compiler that counts its builds: one build (the second export reuses the
    binary), the binaries equal byte for byte and the numbers (``resources/controller.dat``)
    not, and each FMU gives its own Python controller's inputs. A data file of another
    layout or format, a truncated or damaged one (a flipped bit anywhere: its checksum), or an
    edited one (a weight of 1e300 or a NaN, its checksum made to match: the value's plausible
    range) is refused at instantiation with the reason logged; the FMI 2 resource location
    is a file URI (here with a space, percent-encoded)."""
    import shutil
    import zipfile

    from controllers.kernel.constants import Constants
    from cosim.cli import main
    from cosim.core import controller_fmu

    if shutil.which("gcc") is None:
        pytest.skip("gcc not found")
    counter = tmp_path / "builds"
    wrapper = tmp_path / "cc"
    wrapper.write_text("#!/bin/sh\ncase \"$*\" in *model.c*) echo build >> "
                       f"'{counter}';; esac\nexec gcc \"$@\"\n")
    wrapper.chmod(0o755)
    monkeypatch.setenv("CC", str(wrapper))
    monkeypatch.setattr(controller_fmu, "cache_dir", lambda: tmp_path / "cache")
    steps = "time,ref.CA,ref.T\n0,0.5,330\n750,0.55,325\n1500,,\n"
    fmus, archives = {}, {}
    for seed in (3, 7):
        plant, model, steps_csv = _example_case(tmp_path / f"m{seed}", "cstr", seed, steps)
        fmus[seed] = tmp_path / f"Controller{seed}.fmu"
        assert main(["export-fmu", str(model), "--scenario", str(steps_csv), "--out",
                     str(fmus[seed]), "--quiet"]) == 0
        with zipfile.ZipFile(fmus[seed]) as zf:
            archives[seed] = {n: zf.read(n) for n in zf.namelist()}
        py = cosim.run(steps_csv, plant=plant, model=model, figure=False)
        run = cosim.run(steps_csv, plant=plant, controller=str(fmus[seed]), figure=False)
        _same_inputs(run, py, CSTR)
    assert counter.read_text().count("build") == 1
    (b3,), (b7,) = ([d for n, d in a.items() if n.startswith("binaries/")]
                    for a in archives.values())
    assert b3 == b7
    assert archives[3]["resources/controller.dat"] != archives[7]["resources/controller.dat"]

    fmu2 = tmp_path / "Controller2.fmu"
    assert main(["export-fmu", str(model), "--fmi", "2", "--out", str(fmu2), "--quiet"]) == 0
    unzipped = tmp_path / "with space"
    with zipfile.ZipFile(fmu2) as zf:
        zf.extractall(unzipped)
    log: list[str] = []
    _instantiate(unzipped, log).freeInstance()   # read through the percent-encoded URI
    other = Constants()
    other.scalar("X", 1.0)
    data = unzipped / "resources" / "controller.dat"
    good = data.read_bytes()
    for bad, reason in ((other.data(), "is not this library's"),
                        (good[:-8], "expected"), (b"", "not a controller data file"),
                        (b"GKDATA01" + good[8:], "its format GKDATA01 is not this library's"),
                        (_flipped(good, len(good) - 100), "damaged: its checksum"),
                        (_flipped(good, 50), "damaged: its checksum"),   # in the ranges
                        (_edited(good, 0, 1e300), "WZ[0] = 1.0000000000000001e+300 is outside "
                                                  "its plausible range [-1e+06, 1e+06]"),
                        (_edited(good, -1, np.nan), "is NaN")):
        data.write_bytes(bad)
        log.clear()
        with pytest.raises(Exception, match="nstantiate"):
            _instantiate(unzipped, log)
        assert any("controller.dat" in m and reason in m for m in log), log


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
    boxes = {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)}
    _same_inputs(cosim.run(scenario, controller=str(fmu), figure=False), py, boxes)
    default = cosim.run(scenario, figure=False).to_pandas()
    assert not np.array_equal(default["ctrl.qa"], py.to_pandas()["ctrl.qa"])


@pytest.mark.parametrize("law", [{}, PAPER_LAW], ids=["tracking", "paper"])
def test_the_compiled_step_replays_the_softened_phase(law: dict) -> None:
    """Measurements at the top of h1's box, where the estimated state fails the tightened
    rows at the first step: the Python controller solves its softened problem
    (:mod:`controllers.ocp.soft`) instead of falling back, and the compiled step gives the
    same inputs (to the bit), statuses and fallbacks."""
    from controllers.kernel.controller_source import CompiledController, build, design_data
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(**law)
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    softened = [ctrl.diagnostics()["softened"]
                for _ in _replayed(ctrl, compiled, [(1.0, 0.9)] * 12, y0=(1.99, 0.9))]
    assert softened[0] > 0.0, softened   # the estimate starts from the first measurement
    assert ctrl.mpc.summary()["fallbacks"] == 0
    compiled.close()
