"""Variable maps: parsing, conversion, and checks against a real FMU's modelDescription."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.core.fmu import FmuComponent
from cosim.core.varmap import MappedSignal, VarMap, load


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plant.map.toml"
    path.write_text(text)
    return path


def test_load_and_convert(tmp_path: Path) -> None:
    vm = load(write(tmp_path, '[signals.qa]\nvariable = "Fa"\nunit = "l/min"\nscale = 60000.0\n'
                              '[signals.T]\nvariable = "TC"\nscale = 1\noffset = -273.15\n'))
    qa = vm.signals["qa"]
    assert qa == MappedSignal("qa", "Fa", "l/min", 60000.0, 0.0)
    assert qa.to_plant(1e-4) == pytest.approx(6.0)
    assert qa.from_plant(qa.to_plant(3.7e-4)) == pytest.approx(3.7e-4, rel=1e-15)
    assert vm.signals["T"].to_plant(300.0) == pytest.approx(26.85)
    assert vm.lookup("h1") == MappedSignal("h1", "h1")  # unmapped: identity
    assert vm.signal_of("Fa") == "qa" and vm.signal_of("h3") == "h3"


@pytest.mark.parametrize(("text", "words"), [
    ("[signals.qa\nvariable='x'\n", "invalid TOML"),
    ("title = 'x'\n", "unknown top-level key"),
    ("[plant]\n", "no [signals.<name>] tables"),
    ("[signals.qa]\nunit = 'l/min'\n", "signal 'qa': 'variable' (the FMU variable name) is "
                                       "missing"),
    ("[signals.qa]\nvariable = 'Fa'\nscale = 0\n", "signal 'qa': 'scale' must not be zero"),
    ("[signals.qa]\nvariable = 'Fa'\nscale = 'big'\n", "'scale' must be a finite number"),
    ("[signals.qa]\nvariable = 'Fa'\nfactor = 2\n", "unknown key(s) ['factor']"),
    ("[signals.qa]\nvariable = 'F'\n[signals.qb]\nvariable = 'F'\n",
     "signal 'qb': variable 'F' is already mapped by signal 'qa'"),
    ("[signals.qa]\nvariable = 3\n", "signal 'qa': 'variable' must be the FMU variable name "
                                     "as a non-empty string, got 3"),
    ("[signals.qa]\nvariable = ''\n", "'variable' must be the FMU variable name as a "
                                      "non-empty string, got ''"),
])
def test_bad_maps_are_one_line_errors_naming_the_file(tmp_path: Path, text: str,
                                                      words: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(CosimError) as info:
        load(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and words in msg and "\n" not in msg


def test_missing_map_file(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match="variable map not found"):
        load(tmp_path / "none.toml")


def test_check_against_the_four_tank_fmu(tmp_path: Path, fmu2_path: Path) -> None:
    variables = FmuComponent(fmu2_path).variables
    units = {"qa": "m3/s", "qb": "m3/s", "h1": "m", "h2": "m"}
    VarMap.identity().check(variables, ["qa", "qb"], ["h1", "h2"], units)

    missing = load(write(tmp_path, '[signals.qa]\nvariable = "Fa"\n'))
    with pytest.raises(CosimError, match=r"signal 'qa' -> variable 'Fa': the FMU has no such "
                                         "variable"):
        missing.check(variables, ["qa"], ["h1"], units)

    causality = load(write(tmp_path, '[signals.qa]\nvariable = "h3"\n'))
    with pytest.raises(CosimError, match=r"signal 'qa' -> variable 'h3': causality is 'output'"
                                         ", a controller output must drive an FMU input"):
        causality.check(variables, ["qa"], ["h1"], units)
    as_output = load(write(tmp_path, '[signals.h1]\nvariable = "qd1"\n'))
    with pytest.raises(CosimError, match=r"causality is 'input', a measured signal must be an "
                                         "FMU output"):
        as_output.check(variables, ["qa"], ["h1"], units)

    unit = load(write(tmp_path, '[signals.qa]\nvariable = "qa"\nunit = "l/min"\n'
                                'scale = 60000.0\n'))
    with pytest.raises(CosimError) as info:
        unit.check(variables, ["qa"], ["h1"], units)
    msg = str(info.value)
    assert msg.startswith(str(tmp_path / "plant.map.toml"))
    assert "signal 'qa' -> variable 'qa': unit mismatch: the map expects 'l/min', the FMU " \
           "declares 'm3/s'" in msg
    # identity mapping, project unit differs from the FMU's: also a mismatch
    with pytest.raises(CosimError, match=r"^plant.fmu: signal 'h1' \(not in a variable map\): "
                                         "unit mismatch: the controller expects 'cm'"):
        VarMap.identity().check(variables, ["qa"], ["h1"], {"h1": "cm"}, fmu="plant.fmu")


@pytest.mark.parametrize(("entry", "words"), [
    ('[signals.h3]\nvariable = "level3"\n',
     "signal 'h3' -> variable 'level3': the FMU has no such variable"),
    ('[signals.qd1]\nvariable = "qd_1"\n',
     "signal 'qd1' -> variable 'qd_1': the FMU has no such variable"),
    ('[signals.gravity]\nvariable = "g"\n',
     "signal 'gravity' -> variable 'g': causality is 'local'; a map entry must name an FMU "
     "input, output or parameter"),
    ('[signals.S]\nvariable = "S"\nunit = "cm2"\n',
     "signal 'S' -> variable 'S': unit mismatch: the map expects 'cm2', the FMU declares "
     "'m2'"),
])
def test_every_map_entry_is_checked_even_when_the_run_does_not_use_it(
        tmp_path: Path, fmu2_path: Path, entry: str, words: str) -> None:
    """A typo in an entry the controller does not read is found before anything runs."""
    good = '[signals.qa]\nvariable = "qa"\nunit = "m3/s"\n[signals.h1]\nvariable = "h1"\n'
    units = {"qa": "m3/s", "qb": "m3/s", "h1": "m", "h2": "m"}
    comp = FmuComponent(fmu2_path, varmap=load(write(tmp_path, good)))
    comp.check_signals(["qa", "qb"], ["h1", "h2"], units)  # a map of good entries passes
    path = write(tmp_path, good + entry)
    comp = FmuComponent(fmu2_path, varmap=load(path))
    with pytest.raises(CosimError) as info:
        comp.check_signals(["qa", "qb"], ["h1", "h2"], units)
    assert str(info.value) == f"{path}: {words}"


def test_deeply_nested_toml_is_a_one_line_error(tmp_path: Path) -> None:
    path = write(tmp_path, "[signals.qa]\nvariable = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(CosimError) as info:
        load(path)
    assert str(info.value) == f"{path}: invalid TOML: nested too deeply"
