"""``cosim export-fmu`` and ``cosim export-ssp`` as a user meets their errors: one line, the
exit code of the table, and an existing output left as it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main


def _run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    return code, capsys.readouterr().err


def test_export_errors_are_one_line(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    cases = [
        (["export-fmu", "--out", str(tmp_path / "C.zip")], "an FMU's file name ends with .fmu"),
        (["export-fmu", str(tmp_path / "nope.json"), "--out", str(tmp_path / "C.fmu")],
         "nope.json"),
        (["export-fmu", "--controller", str(tmp_path / "nope.json"),
          "--out", str(tmp_path / "C.fmu")], "controller file not found"),
        (["export-ssp", "--controller", str(tmp_path / "none.fmu")],
         "controller FMU not found"),
    ]
    for argv, reason in cases:
        code, err = _run(capsys, *argv)
        assert code == 2, (argv, err)
        assert err.count("\n") == 1 and reason in err, (argv, err)
    assert not list(tmp_path.glob("*.fmu"))


def test_a_failed_build_keeps_the_existing_fmu(capsys: pytest.CaptureFixture, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The FMU's compiler fails (``false`` in its place): exit 2 naming the failure, the FMU
    already at ``--out`` byte for byte as it was."""
    import shutil

    out = tmp_path / "Controller.fmu"
    out.write_bytes(b"the previous FMU")
    monkeypatch.setattr("cosim.core.controller_fmu.compiler", lambda: shutil.which("false"))
    code, err = _run(capsys, "export-fmu", "--out", str(out))
    assert code == 2 and err.count("\n") == 1
    assert "compiling the controller FMU failed" in err, err
    assert out.read_bytes() == b"the previous FMU"
    assert [p.name for p in tmp_path.iterdir()] == ["Controller.fmu"]


def test_an_ssp_needs_fmus_that_belong_together(capsys: pytest.CaptureFixture,
                                                 controller_fmus: dict[int, Path],
                                                 tmp_path: Path) -> None:
    """A controller and a plant with no connection by name, and an unknown set-point: one
    line each, no file written."""
    other = Path(__file__).resolve().parents[3] / "fmus" / "FourTank3.fmu"
    code, err = _run(capsys, "export-ssp", "--plant", str(other), "--controller",
                     str(controller_fmus[2]), "--setpoint", "ref.h9=1", "--out",
                     str(tmp_path / "x.ssp"))
    assert code == 2 and err.count("\n") == 1 and "--setpoint ref.h9" in err, err
    assert not (tmp_path / "x.ssp").exists()


@pytest.mark.parametrize(("args", "reason"), [
    (["--parameter", "N=40"], "--parameter N: not a parameter of"),
    (["--parameter", "R.qa=-1"], "--parameter R.qa=-1: outside its range [0, inf]"),
    (["--parameter", "offset_filter=2"], "--parameter offset_filter=2: outside its range [0, 1]"),
    (["--parameter", "R.qa=x"], "--parameter R.qa=x: expected NAME=VALUE with a number"),
    (["--parameter", "offset_filter=nan"], "--parameter offset_filter=nan: expected a finite"),
    (["--parameter", "R.qa=inf"], "--parameter R.qa=inf: expected a finite number"),
    # inside the declared box, refused by the FMU itself: the rehearsal finds it
    (["--parameter", "R.qa=0"], "cannot set R.qa = 0: must keep R positive definite"),
    (["--parameter", "offset_filter=0"], "cannot set offset_filter = 0: must be in (0, 1]"),
    (["--setpoint", "ref.h1=nan"], "--setpoint ref.h1=nan: expected a finite number"),
    (["--setpoint", "ref.h1=5"], "--setpoint ref.h1=5: outside its range [0, 2]"),
    (["--stop", "-5"], "--stop -5.0: expected a finite stop time of at least one step (25 s)"),
    (["--stop", "inf"], "--stop inf: expected a finite stop time"),
])
def test_an_ssp_that_cannot_run_is_not_written(capsys: pytest.CaptureFixture,
                                               controller_fmus: dict[int, Path],
                                               tmp_path: Path, args: list[str],
                                               reason: str) -> None:
    """``--parameter``: a name the controller has, a finite value within its declared range
    that the controller takes; ``--setpoint``: finite, inside the output's box; ``--stop``:
    at least one step. One line, exit 2, no file written: libcosim would refuse or abort."""
    code, err = _run(capsys, "export-ssp", "--controller", str(controller_fmus[2]), *args,
                     "--out", str(tmp_path / "x.ssp"))
    assert code == 2 and err.count("\n") == 1 and reason in err, err
    assert not (tmp_path / "x.ssp").exists()


def test_an_ssp_of_a_controller_that_is_no_fmu_is_one_line(capsys: pytest.CaptureFixture,
                                                           tmp_path: Path) -> None:
    bad = tmp_path / "X.fmu"
    bad.write_text("not a zip archive")
    code, err = _run(capsys, "export-ssp", "--controller", str(bad), "--out",
                     str(tmp_path / "x.ssp"))
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{bad}: cannot read modelDescription.xml" in err
    assert not (tmp_path / "x.ssp").exists()


def test_a_model_no_law_can_control_is_named_in_the_users_terms(
        capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    """The shipped model with its candidate, recurrent and output weights scaled up by 100
    (rho_s >= 1: no certificate, and its steady outputs all far outside the box): export-fmu
    and run refuse it in one line that says why in the user's units, never a library's
    internal message (scipy's "Invalid input for linprog"), and write nothing."""
    import json

    from controllers.model import DEFAULT_MODEL

    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    for key in ("W_h", "U_h", "U_o"):
        doc[key] = (100 * np.asarray(doc[key])).tolist()
    model = tmp_path / "scaled.json"
    model.write_text(json.dumps(doc))
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,,\n")
    for argv in (["export-fmu", str(model), "--out", str(tmp_path / "C.fmu")],
                 ["run", str(scenario), "--model", str(model), "--out", str(tmp_path / "o")]):
        code, err = _run(capsys, *argv)
        assert code == 2 and err.count("\n") == 1, err
        assert "the model is not usable" in err and "cannot be steered" in err, err
        assert "the closest reachable equilibrium output is h1=" in err, err
        assert "linprog" not in err and "SW" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv", "scaled.json"]
