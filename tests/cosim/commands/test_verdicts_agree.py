"""One verdict read everywhere: for models that fail in different ways, ``cosim certify``
(its verdict line, exit code and saved ``certificate``), ``cosim run`` and ``cosim
export-fmu`` (and, for the named cases, ``cosim tune``, ``cosim campaign`` and the exported
controller FMU) agree on whether the robust MPC runs the model, and a refusal is the same
sentence everywhere, never a library's message; a usable model runs a scenario with the model
itself as the plant, without a constraint violation (the Python controller, a campaign's run
and the controller FMU alike, the FMU's inputs those of the Python controller to the bit).
Named cases, then generated ones (hypothesis): the shipped model with a weight array scaled,
its gate biases shifted, its output box narrowed."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controllers.model import DEFAULT_MODEL
from cosim.cli import main

#: The scenario: a set-point step from ``start`` to ``{h1},{h2}`` (each case's).
SCENARIO = "time,ref.h1,ref.h2\n0,{start}\n500,{h1},{h2}\n1000,,\n"


def _scaled(*keys: str, by: float) -> Callable[[dict], None]:
    def edit(doc: dict) -> None:
        for key in keys:
            doc[key] = (by * np.asarray(doc[key])).tolist()
    return edit


def _narrow_box(doc: dict) -> None:
    """An output box narrower than the model's largest test error (0.11 m)."""
    for channel in doc["problem"]["outputs"]:
        channel["min"], channel["max"] = 0.6, 0.7


def _saturated(doc: dict) -> None:
    """An update gate that saturates: sigma_z rounds to 1, no certificate exists."""
    doc["b_z"] = [v + 50.0 for v in doc["b_z"]]


#: name -> (edit of the shipped model, the second set-point, exit code of certify)
CASES = {
    "certified": (lambda doc: None, "1.2,1.3", 0),
    "uncertified": (lambda doc: None, "1.97,1.0", 1),   # next to the box's edge
    "recurrent-x10": (_scaled("U_h", by=10.0), "1.2,1.3", 1),   # nu = 9.8: s measured
    "scaled-x100": (_scaled("W_h", "U_h", "U_o", by=100.0), "1.2,1.3", 2),
    "narrow-box": (_narrow_box, "0.65,0.65", 2),
}
#: What never reaches the user.
INTERNAL = ("Traceback", "linprog", "ValueError", "casadi", "numpy", "SW")


def _run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _violations(summary: Path) -> int:
    doc = json.loads(summary.read_text())
    return sum(v["count"] for v in doc["kpis"]["violations"].values())


def _agree(doc: dict, setpoint: str, folder: Path, capsys: pytest.CaptureFixture,
           start: str = "0.65,0.65", every_command: bool = False) -> int:
    """certify, run (the model as the plant) and export-fmu on the model ``doc`` with the
    scenario's second set-point ``setpoint`` (``every_command``: tune, a one-run campaign and
    the exported FMU in closed loop too): the same verdict, the same refusal sentence, no
    internal message, no violation on a usable model; certify's exit code."""
    model = folder / "model.json"
    model.write_text(json.dumps(doc))
    scenario = folder / "s.csv"
    h1, h2 = setpoint.split(",")
    scenario.write_text(SCENARIO.format(start=start, h1=h1, h2=h2))
    code, out, err = _run(capsys, "certify", str(model), "--save", "--setpoint", start,
                          "--setpoint", setpoint)
    assert code in (0, 1, 2) and not any(word in err for word in INTERNAL), err
    verdict = json.loads(model.read_text())["certificate"]
    usable = code < 2
    assert verdict["usable"] is usable and verdict["certified"] is (code == 0), (code, err)
    why = None
    if not usable:
        assert "NOT USABLE" in out
        why = err.splitlines()[-1].removeprefix("cosim certify: not usable: ")
        assert why == verdict["unusable_reason"] and "fix: " in why
    commands = [["run", str(scenario), "--model", str(model), "--plant", f"model:{model}",
                 "--out", str(folder / "run"), "--quiet", "--no-figure"],
                ["export-fmu", str(model), "--out", str(folder / "C.fmu"), "--quiet"]]
    if every_command:   # the FMU designed for the scenario's set-points, as cosim run is
        commands[1][2:2] = ["--scenario", str(scenario)]
    if every_command:
        spec = folder / "campaign.toml"
        spec.write_text(f'[campaign]\nname = "agree"\nruns = 1\nseed = 1\nscenario = '
                        f'"{scenario.name}"\nplant = "model:{model.name}"\nmodel = '
                        f'"{model.name}"\n')
        # tune's verdict is read where it loads the model: the runs with the gains off
        # (tests/cosim/commands/test_cli_tune.py) add minutes and nothing to it
        commands += [["tune", str(model), "--quiet", "--gain-uncertainty", "0"],
                     ["campaign", str(spec), "--out", str(folder / "camp"), "--quiet"]]
    for argv in commands:
        status, _, err = _run(capsys, *argv)
        assert not any(word in err for word in INTERNAL), err
        if usable:
            assert status == 0, err
        elif argv[0] == "campaign":   # the refusal after the spec's file:line and variant
            assert status == 2 and err.startswith(f"cosim campaign: error: {spec}:") and \
                err.endswith(f"controller 'mpc': the model is not usable: {why}\n"), err
        else:
            assert status == 2 and err == (f"cosim {argv[0]}: error: controller 'mpc': the "
                                           f"model is not usable: {why}\n"), err
    if usable:
        assert _violations(folder / "run" / "summary.json") == 0
        if every_command:
            assert [_violations(f / "summary.json")
                    for f in sorted((folder / "camp" / "runs").iterdir())] == [0]
            status, _, err = _run(capsys, "run", str(scenario), "--controller",
                                  str(folder / "C.fmu"), "--plant", f"model:{model}", "--out",
                                  str(folder / "fmu"), "--quiet", "--no-figure")
            assert status == 0 and _violations(folder / "fmu" / "summary.json") == 0, err
            python, fmu = (np.genfromtxt(folder / name / "results.csv", delimiter=",",
                                         names=True) for name in ("run", "fmu"))
            for column in ("ctrlqa", "ctrlqb"):   # the FMU's inputs are the Python ones
                assert np.array_equal(python[column], fmu[column]), column
    else:
        assert not (folder / "run").exists() and not (folder / "C.fmu").exists()
        assert not (folder / "camp" / "runs").exists()
    return code


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_certify_run_and_export_agree(case: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    edit, setpoint, exit_code = CASES[case]
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    edit(doc)
    assert _agree(doc, setpoint, tmp_path, capsys, every_command=True) == exit_code


WEIGHTS = ("W_z", "U_z", "W_r", "U_r", "W_h", "U_h", "U_o")


@st.composite
def damaged_models(draw: st.DrawFn) -> dict:
    """The shipped model, one to two of its weight arrays scaled (by 0.3 to 30), its update
    gate's bias shifted, or its output box narrowed."""
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    for _ in range(draw(st.integers(1, 2))):
        kind = draw(st.sampled_from(("scale", "scale", "bias", "box")))
        if kind == "scale":
            _scaled(draw(st.sampled_from(WEIGHTS)),
                    by=draw(st.sampled_from((0.3, 0.5, 2.0, 3.0, 10.0, 30.0))))(doc)
        elif kind == "bias":
            shift = draw(st.sampled_from((-5.0, 2.0, 5.0)))
            doc["b_z"] = [v + shift for v in doc["b_z"]]
        else:
            half = draw(st.sampled_from((0.05, 0.2, 0.5)))
            for channel in doc["problem"]["outputs"]:
                channel["min"], channel["max"] = 1.0 - half, 1.0 + half
    return doc


@pytest.mark.slow
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(doc=damaged_models())
def test_generated_damage_gets_one_verdict(doc: dict, tmp_path_factory: pytest.TempPathFactory,
                                            capsys: pytest.CaptureFixture) -> None:
    box = doc["problem"]["outputs"][0]
    mid = 0.5 * (box["min"] + box["max"])
    low = box["min"] + 0.4 * (box["max"] - box["min"])
    _agree(doc, f"{mid},{mid}", tmp_path_factory.mktemp("model"), capsys,
           start=f"{low},{low}")


def test_a_model_without_a_certificate_is_refused_alike(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    """An update gate that saturates (sigma_z rounds to 1): no certificate can be computed;
    certify and run say so in the same words, exit 2."""
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    _saturated(doc)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    scenario.write_text(SCENARIO.format(start="0.65,0.65", h1=1.2, h2=1.3))
    c1, _, certify = _run(capsys, "certify", str(model), "--quiet")
    c2, _, run = _run(capsys, "run", str(scenario), "--model", str(model), "--out",
                      str(tmp_path / "run"))
    assert c1 == c2 == 2
    assert certify.removeprefix("cosim certify: error: ") == run.removeprefix(
        "cosim run: error: ")
    assert "sigma_z" in run and "rounds to 1" in run and run.count("\n") == 1


@pytest.fixture(scope="module")
def few_samples(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The four tanks identified from a handful of samples: 400 rows of data (280 to train
    on), one small GRU, a brief training."""
    folder = tmp_path_factory.mktemp("few")
    data, model = folder / "data.csv", folder / "gru.json"
    assert main(["generate-data", "--steps", "400", "--out", str(data), "--quiet"]) == 0
    assert main(["train", str(data), "--epochs", "40", "--n", "4", "--seeds", "1",
                 "--out", str(model), "--quiet"]) == 0
    return json.loads(model.read_text())


@pytest.mark.slow
def test_a_model_trained_on_a_handful_of_samples_gets_one_verdict(
        few_samples: dict, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert _agree(few_samples, "1.0,1.0", tmp_path, capsys, start="0.8,0.8") in (0, 1, 2)


@pytest.mark.slow
def test_the_papers_law_runs_a_model_the_theory_rejects_on_its_measured_weight(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The shipped model with U_h scaled by 10 (nu = 9.8) under the paper's law: certify
    says usable uncertified (exit 1), and the Python controller and its FMU run the set-point
    step on the model itself without a violation (the uncertified design's set-point checks
    stand on its measured terminal weight, not on nu < 1)."""
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    _scaled("U_h", by=10.0)(doc)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    scenario.write_text(SCENARIO.format(start="0.65,0.65", h1=1.2, h2=1.3))
    code, out, err = _run(capsys, "certify", str(model), "--law", "paper", "--setpoint",
                          "0.65,0.65", "--setpoint", "1.2,1.3")
    assert code == 1 and "usable: the robust MPC runs uncertified" in out, err
    paper = ["--option", 'law="paper"']
    status, _, err = _run(capsys, "run", str(scenario), "--model", str(model), *paper,
                          "--plant", f"model:{model}", "--out", str(tmp_path / "run"),
                          "--quiet", "--no-figure")
    assert status == 0 and _violations(tmp_path / "run" / "summary.json") == 0, err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["controller_summary"]["certified"] is False
    assert summary["controller_summary"]["tightening"] == "measured"
    status, _, err = _run(capsys, "export-fmu", str(model), *paper, "--out",
                          str(tmp_path / "C.fmu"), "--quiet")
    assert status == 0, err
    status, _, err = _run(capsys, "run", str(scenario), "--controller", str(tmp_path / "C.fmu"),
                          "--plant", f"model:{model}", "--out", str(tmp_path / "fmu"),
                          "--quiet", "--no-figure")
    assert status == 0 and _violations(tmp_path / "fmu" / "summary.json") == 0, err
    # the exported law admits the set-points the Python law admits (it held its inputs at
    # every step, unseen, while its design check asked nu < 1 of the uncertified design)
    py, fmu = (np.loadtxt(tmp_path / r / "results.csv", delimiter=",", skiprows=1,
                          usecols=(7, 8)) for r in ("run", "fmu"))   # ctrl.qa, ctrl.qb
    assert np.allclose(py, fmu, rtol=0, atol=1e-9)
