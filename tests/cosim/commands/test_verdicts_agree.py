"""One verdict read everywhere: for models that fail in different ways, ``cosim certify``
(its verdict line, exit code and saved ``certificate``), ``cosim run`` and ``cosim
export-fmu`` agree on whether the robust MPC runs the model, and a refusal is the same
sentence everywhere, never a library's message; a usable model runs a scenario with the model
itself as the plant, without a constraint violation."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from controllers.model import DEFAULT_MODEL
from cosim.cli import main

#: The scenario: a set-point step to ``{h1},{h2}`` (each case's).
SCENARIO = "time,ref.h1,ref.h2\n0,0.65,0.65\n500,{h1},{h2}\n1000,,\n"


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
    "recurrent-x10": (_scaled("U_h", by=10.0), "1.2,1.3", 2),             # nu = 9.8
    "scaled-x100": (_scaled("W_h", "U_h", "U_o", by=100.0), "1.2,1.3", 2),
    "narrow-box": (_narrow_box, "0.65,0.65", 2),
}
#: What never reaches the user.
INTERNAL = ("Traceback", "linprog", "ValueError", "casadi", "numpy", "SW")


def _run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_certify_run_and_export_agree(case: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    edit, setpoint, exit_code = CASES[case]
    usable = exit_code < 2
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    edit(doc)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    h1, h2 = setpoint.split(",")
    scenario.write_text(SCENARIO.format(h1=h1, h2=h2))

    code, out, err = _run(capsys, "certify", str(model), "--save", "--setpoint", setpoint)
    verdict = json.loads(model.read_text())["certificate"]
    assert code == exit_code and verdict["usable"] is usable, (code, err)
    assert verdict["certified"] is (code == 0)
    if usable:
        assert verdict["unusable_reason"] is None
    else:
        assert "NOT USABLE" in out
        why = err.splitlines()[-1].removeprefix("cosim certify: not usable: ")
        assert why == verdict["unusable_reason"] and "fix: " in why

    for argv in (["run", str(scenario), "--model", str(model), "--plant", f"model:{model}",
                  "--out", str(tmp_path / "run"), "--quiet", "--no-figure"],
                 ["export-fmu", str(model), "--out", str(tmp_path / "C.fmu"), "--quiet"]):
        code, _, err = _run(capsys, *argv)
        assert not any(word in err for word in INTERNAL), err
        if usable:
            assert code == 0, err
        else:
            assert code == 2 and err == (f"cosim {argv[0]}: error: controller 'mpc': the "
                                         f"model is not usable: {why}\n"), err
    if usable:
        summary = json.loads((tmp_path / "run" / "summary.json").read_text())
        assert sum(v["count"] for v in summary["kpis"]["violations"].values()) == 0
    else:
        assert not (tmp_path / "run").exists() and not (tmp_path / "C.fmu").exists()


def test_a_model_without_a_certificate_is_refused_alike(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    """An update gate that saturates (sigma_z rounds to 1): no certificate can be computed;
    certify and run say so in the same words, exit 2."""
    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    _saturated(doc)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    scenario.write_text(SCENARIO.format(h1=1.2, h2=1.3))
    c1, _, certify = _run(capsys, "certify", str(model), "--quiet")
    c2, _, run = _run(capsys, "run", str(scenario), "--model", str(model), "--out",
                      str(tmp_path / "run"))
    assert c1 == c2 == 2
    assert certify.removeprefix("cosim certify: error: ") == run.removeprefix(
        "cosim run: error: ")
    assert "sigma_z" in run and "rounds to 1" in run and run.count("\n") == 1
