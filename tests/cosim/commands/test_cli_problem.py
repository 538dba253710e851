"""``--problem`` through the commands: a plant FMU bound to a problem in other names and units
(``Reactor.fmu`` of :mod:`tests.cosim.units_fmu`), and bad problem files, each one line naming
the file and line, exit 2, nothing run (``generate-data``, ``run``, ``campaign``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.core import datagen
from tests.cosim import units_fmu

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def reactor(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return units_fmu.build(tmp_path_factory.mktemp("reactor"))


@pytest.fixture()
def files(tmp_path: Path, reactor: Path) -> Path:
    """A folder with the reactor's problem, a scenario and a campaign spec for them."""
    (tmp_path / "reactor.toml").write_text(units_fmu.PROBLEM)
    (tmp_path / "steps.csv").write_text(units_fmu.SCENARIO)
    (tmp_path / "spec.toml").write_text(
        f'[campaign]\nruns = 1\nscenario = "steps.csv"\ncontroller = "pi"\n'
        f'plant = "{reactor}"\nproblem = "reactor.toml"\n')
    return tmp_path


def columns(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True, deletechars="")
    return {name: data[name] for name in data.dtype.names}


# -- working runs -------------------------------------------------------------------------------

def test_run_converts_both_ways_and_tracks(files: Path, reactor: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    out = files / "out"
    code = main(["run", str(files / "steps.csv"), "--plant", str(reactor), "--problem",
                 str(files / "reactor.toml"), "--controller", "pi", "--out", str(out),
                 "--no-figure"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert "IAE CA=" in stdout and "mol/L·s" in stdout and "K·s" in stdout
    c = columns(out / "results.csv")
    # the FMU's 625 mol/m3 and 23.75 degC, in the problem's mol/L and K
    assert c["plant.CA"][0] == pytest.approx(0.625) and c["plant.T"][0] == pytest.approx(
        296.9, abs=0.01)
    # what the FMU received one step later: L/min -> m3/s, K -> degC
    assert np.allclose(c["plant.F_echo"][1:], c["ctrl.F"][:-1] / 60000.0, rtol=1e-13)
    assert np.allclose(c["plant.Tc_echo"][1:], c["ctrl.Tc"][:-1] - 273.15, rtol=1e-13)
    # the PI loops track the set-points in the problem's units
    assert abs(c["plant.CA"][-1] - 0.7) < 0.01 and abs(c["plant.T"][-1] - 305.0) < 0.3
    assert c["ctrl.F"].min() >= 0.5 and c["ctrl.F"].max() <= 2.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["problem"] == "reactor"
    assert summary["problem_source"] == str(files / "reactor.toml")
    assert summary["signals"]["outputs"]["T"]["unit"] == "K"


def test_an_isolated_plant_converts_the_same(files: Path, reactor: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    """The binding travels to the FMU's worker process (--isolate) with the conversions."""
    for name, extra in (("a", []), ("b", ["--isolate"])):
        code = main(["run", str(files / "steps.csv"), "--plant", str(reactor), "--problem",
                     str(files / "reactor.toml"), "--controller", "pi", "--out",
                     str(files / name), "--no-figure", "--quiet", *extra])
        assert code == 0, capsys.readouterr().err
    assert (files / "a" / "results.csv").read_bytes() == \
        (files / "b" / "results.csv").read_bytes()


def test_the_python_api_takes_the_problem(files: Path, reactor: Path) -> None:
    from cosim.api import run

    output = run(files / "steps.csv", plant=reactor, controller="pi",
                 problem=files / "reactor.toml")
    assert output.status == "ok" and output.summary["problem"] == "reactor"
    assert output.summary["problem_source"] == str(files / "reactor.toml")
    table = output.to_pandas()
    assert table["plant.T"].iloc[0] == pytest.approx(296.9, abs=0.01)


def test_generate_data_records_the_problems_units(files: Path, reactor: Path) -> None:
    """Tc here drives the FMU's tunable parameter k0 (in 1/min; the FMU's is 1/s)."""
    problem = files / "k.toml"
    problem.write_text(units_fmu.PROBLEM.replace('[inputs.Tc]\nunit = "K"\nmin = 283.15\n'
                                                 'max = 343.15',
                                                 '[inputs.k]\nunit = "1/min"\nvariable = "k0"'
                                                 '\nmin = 0.03\nmax = 0.09').split("[pi]")[0])
    out = files / "d.csv"
    assert main(["generate-data", "--plant", str(reactor), "--problem", str(problem),
                 "--steps", "60", "--seed", "4", "--out", str(out), "--quiet"]) == 0
    data = datagen.read_csv(out)
    assert data.input_names == ["F", "k"]
    y = dict(zip(data.output_names, data.y.T, strict=True))
    assert data.u[:, 0].min() >= 0.5 and data.u[:, 0].max() <= 2.0   # L/min, the box
    assert np.allclose(y["F_echo"][1:], data.u[:-1, 0] / 60000.0, rtol=1e-13)
    assert np.allclose(y["k_echo"][1:], data.u[:-1, 1] / 60.0, rtol=1e-13)
    assert y["T"].min() > 273.15 and y["CA"].max() < 1.0               # K, mol/L
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["problem"]["inputs"][0]["variable"] == "F_in"


def test_a_tunable_parameter_input_in_closed_loop(files: Path, reactor: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    """A problem input bound to the FMU's tunable parameter k0 (the master drives it)."""
    problem = files / "k.toml"
    problem.write_text(units_fmu.PROBLEM.replace(
        '[inputs.Tc]\nunit = "K"\nmin = 283.15\nmax = 343.15',
        '[inputs.k]\nunit = "1/min"\nvariable = "k0"\nmin = 0.03\nmax = 0.09').replace(
        '{ output = "CA", input = "F", K = 2.0, Ti = 300.0 },\n'
        '    { output = "T", input = "Tc", K = 1.0, Ti = 150.0 },',
        '{ output = "CA", input = "k", K = -0.1, Ti = 300.0 },\n'
        '    { output = "T", input = "F", K = -0.1, Ti = 300.0 },'))
    code = main(["run", str(files / "steps.csv"), "--plant", str(reactor), "--problem",
                 str(problem), "--controller", "pi", "--out", str(files / "k"), "--quiet",
                 "--no-figure"])
    assert code == 0, capsys.readouterr().err
    c = columns(files / "k" / "results.csv")
    assert np.ptp(c["ctrl.k"]) > 0.001
    assert np.allclose(c["plant.k_echo"][1:], c["ctrl.k"][:-1] / 60.0, rtol=1e-13)


def test_a_campaign_binds_its_plant_to_the_spec_problem(files: Path) -> None:
    """The spec's problem reaches the workers as a file; the binding as data (in-process)."""
    from cosim.campaign import engine, spec, task

    plan = engine.prepare(spec.load(files / "spec.toml"))
    (t,) = plan.tasks
    assert t["options"]["problem"] == "problem_0.toml" and t["binding"] is not None
    assert plan.assets.files["problem_0.toml"] == units_fmu.PROBLEM.encode()
    result = task.run_task(t, plan.assets)["result"]
    assert result.status == "ok", result.reason
    row = dict(zip(result.columns, result.rows[-1], strict=True))
    assert abs(row["plant.T"] - 305.0) < 0.3 and abs(row["plant.CA"] - 0.7) < 0.01


def test_a_problem_that_contradicts_the_models_exits_2_naming_both(
        files: Path, capsys: pytest.CaptureFixture) -> None:
    code = main(["run", str(ROOT / "scenarios" / "paper_steps.csv"), "--problem",
                 str(files / "reactor.toml"), "--out", str(files / "x")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert f"--problem {files / 'reactor.toml'} contradicts the problem of" in err
    assert "fourtank_gru.json" in err and "name 'fourtank' vs 'reactor'" in err
    assert not (files / "x").exists()


def test_the_four_tank_problem_given_is_the_default(tmp_path: Path, fmu2_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.7,0.6\n500,,\n")
    for name, extra in (("a", []), ("b", ["--problem", str(ROOT / "fmus" / "fourtank" /
                                                          "problem.toml")])):
        assert main(["run", str(scenario), "--controller", "pi", "--quiet", "--no-figure",
                     "--out", str(tmp_path / name), *extra]) == 0, capsys.readouterr().err
    assert (tmp_path / "a" / "results.csv").read_bytes() == \
        (tmp_path / "b" / "results.csv").read_bytes()


# -- bad problem files, through three commands -------------------------------------------------

def _replace(old: str, new: str, count: int = 1) -> Callable[[str], str]:
    def edit(text: str) -> str:
        assert old in text
        return text.replace(old, new, count)
    return edit


_NO_INPUTS = units_fmu.PROBLEM.split("[inputs.F]")[0] + \
    units_fmu.PROBLEM[units_fmu.PROBLEM.index("[outputs.CA]"):units_fmu.PROBLEM.index("[pi]")]
_NO_OUTPUTS = units_fmu.PROBLEM[:units_fmu.PROBLEM.index("[outputs.CA]")]

#: name -> (edit of the problem text, the text on the line named, words of the message)
CASES: dict[str, tuple[Callable[[str], str], str, str]] = {
    "invalid TOML": (lambda t: t + "oops = \n", "oops = ", "invalid TOML"),
    "unknown key": (_replace('unit = "mol/L"', 'unit = "mol/L"\nunits = "x"'), 'units = "x"',
                    "unknown key 'units' in [outputs.CA]"),
    "missing min": (_replace("min = 0.5\n", ""), "[inputs.F]", "[inputs.F] has no 'min'"),
    "missing max": (_replace("max = 0.9\n", ""), "[outputs.CA]", "[outputs.CA] has no 'max'"),
    "missing unit": (_replace('unit = "K"\nmin = 283.15', 'min = 283.15'), "[inputs.Tc]",
                     "[inputs.Tc] has no 'unit'"),
    "missing Ts": (_replace("Ts = 10.0\n", ""), "[problem]", "[problem] has no 'Ts'"),
    "min >= max": (_replace("max = 2.0", "max = 0.5"), "max = 0.5",
                   "[inputs.F] needs min < max, got min = 0.5, max = 0.5"),
    "infinite": (_replace("max = 0.9", "max = inf"), "max = inf", "'max' must be finite"),
    "nan": (_replace("min = 0.3", "min = nan"), "min = nan", "'min' must be finite"),
    "duplicate name": (_replace("[outputs.T]", "[outputs.Tc]"), "[outputs.Tc]",
                       "name 'Tc' is used twice (inputs and outputs)"),
    "duplicate table": (lambda t: t + '[inputs.F]\nunit = "W"\n', '[inputs.F]\nunit = "W"',
                        "invalid TOML (Cannot declare ('inputs', 'F') twice)"),
    "no inputs": (lambda t: _NO_INPUTS, "[problem]", "the problem has no inputs"),
    "no outputs": (lambda t: _NO_OUTPUTS, "[problem]", "the problem has no outputs"),
    "signal the FMU lacks": (_replace('variable = "F_in"', 'variable = "Fin"'),
                             'variable = "Fin"',
                             "input 'F' -> FMU variable 'Fin': Reactor.fmu has no such "
                             "variable"),
    "wrong causality": (_replace('unit = "mol/L"', 'unit = "mol/L"\nvariable = "k0"'),
                        'variable = "k0"', "output 'CA' -> FMU variable 'k0': the variable is "
                                           "of causality 'parameter'"),
    "input on an output": (_replace('variable = "F_in"', 'variable = "level"'),
                           'variable = "level"', "input 'F' -> FMU variable 'level': the "
                                                 "variable is of causality 'output'"),
    "non-real": (_replace('unit = "mol/L"', 'unit = "mol/L"\nvariable = "mode"'),
                 'variable = "mode"', "the variable is of type 'Integer'"),
    "unit the FMU contradicts": (_replace('unit = "mol/L"', 'unit = "K"'),
                                 'unit = "K"\nmin = 0.3',
                                 "output 'CA' -> FMU variable 'CA': a unit the FMU "
                                 "contradicts: the problem says 'K', Reactor.fmu declares "
                                 "'mol/m3'"),
    "a date in [train]": (lambda t: t + "[train]\nepochs = 1979-05-27\n",
                          "epochs = 1979-05-27", "[train] 'epochs' must be a number, string, "
                                                 "boolean, list or table, got date"),
    "[mpc] not a table": (lambda t: "# a plant\n\nmpc = 3\n" + t, "mpc = 3",
                          "[mpc] must be a table of options"),
    "unit nobody knows": (_replace('unit = "L/min"', 'unit = "Lpmm"'), 'unit = "Lpmm"',
                          "the problem's unit 'Lpmm' is not understood"),
}


def _line(text: str, anchor: str) -> int:
    """The line of ``text`` on which ``anchor`` (found once) starts."""
    assert text.count(anchor) == 1, anchor
    return text.count("\n", 0, text.index(anchor)) + 1


def _command(kind: str, files: Path, reactor: Path) -> list[str]:
    problem = str(files / "reactor.toml")
    if kind == "generate-data":
        return ["generate-data", "--plant", str(reactor), "--problem", problem, "--steps",
                "20", "--out", str(files / "out" / "d.csv"), "--quiet"]
    if kind == "run":
        return ["run", str(files / "steps.csv"), "--plant", str(reactor), "--problem", problem,
                "--controller", "pi", "--out", str(files / "out"), "--quiet"]
    return ["campaign", str(files / "spec.toml"), "--out", str(files / "out"), "--quiet"]


@pytest.mark.parametrize("command", ["generate-data", "run", "campaign"])
@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_problem_is_one_line_with_file_and_line_exit_2_nothing_run(
        case: str, command: str, files: Path, reactor: Path,
        capsys: pytest.CaptureFixture) -> None:
    edit, anchor, words = CASES[case]
    path = files / "reactor.toml"
    text = edit(units_fmu.PROBLEM)
    path.write_text(text)
    code = main(_command(command, files, reactor))
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and out == ""
    assert f"{path}:{_line(text, anchor)}" in err, err
    assert words in err, err
    assert err.startswith(f"cosim {command}: error: ")
    if command == "campaign":   # the spec's problem key, then the problem file's line
        assert f"{files / 'spec.toml'}:6: variant 'pi': {path}:" in err
    assert not (files / "out").exists()


def test_a_campaign_problem_that_is_not_there_names_the_spec_line(
        files: Path, capsys: pytest.CaptureFixture) -> None:
    spec = files / "spec.toml"
    spec.write_text(spec.read_text().replace('problem = "reactor.toml"', 'problem = "no.toml"'))
    assert main(["campaign", str(spec), "--out", str(files / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{spec}:6: problem = 'no.toml': problem file not found" in err
