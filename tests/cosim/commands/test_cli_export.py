"""``cosim export-fmu`` and ``cosim export-ssp`` as a user meets their errors: one line, the
exit code of the table, and an existing output left as it was."""

from __future__ import annotations

from pathlib import Path

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


@pytest.mark.parametrize(("item", "reason"), [
    ("N=40", "--parameter N: not a parameter of"),
    ("R.qa=-1", "--parameter R.qa=-1: outside its range [0.0, inf]"),
    ("offset_filter=2", "--parameter offset_filter=2: outside its range [0.0, 1.0]"),
    ("R.qa=x", "--parameter R.qa=x: expected NAME=VALUE with a number"),
])
def test_an_ssps_controller_parameters_are_checked(capsys: pytest.CaptureFixture,
                                                   controller_fmus: dict[int, Path],
                                                   tmp_path: Path, item: str,
                                                   reason: str) -> None:
    """``--parameter``: a name the controller has, within its declared range; one line, no
    file written."""
    code, err = _run(capsys, "export-ssp", "--controller", str(controller_fmus[2]),
                     "--parameter", item, "--out", str(tmp_path / "x.ssp"))
    assert code == 2 and err.count("\n") == 1 and reason in err, err
    assert not (tmp_path / "x.ssp").exists()
