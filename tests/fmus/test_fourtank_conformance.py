"""Third-party proofs that the plant FMUs are standard-clean: fmpy validate, fmutool -check,
and the model descriptions' interface (names, causalities, units)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

VENV_BIN = Path(sys.executable).parent
INPUTS = ("qa", "qb", "qd1", "qd2", "qd3", "qd4")
OUTPUTS = ("h1", "h2", "h3", "h4")
TUNABLES = ("S", "a1", "a2", "a3", "a4", "gamma_a", "gamma_b")
START_LEVELS = ("h1_start", "h2_start", "h3_start", "h4_start")


def _tool(name: str) -> str:
    path = VENV_BIN / name
    if path.exists():
        return str(path)
    found = shutil.which(name)
    assert found, f"{name} is not installed (pip install -e '.[dev]')"
    return found


def _fmpy_validate(fmu: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [_tool("fmpy"), "validate", str(fmu)], capture_output=True, text=True, timeout=120
    )


def _fmutool_check(fmu: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [_tool("fmutool"), "-input", str(fmu), "-check"],
        capture_output=True,
        text=True,
        timeout=120,
    )


def _broken_copy(fmu: Path, tmp_path: Path) -> Path:
    """A copy of ``fmu`` whose output h1 claims variability 'fixed' (not allowed)."""
    out = tmp_path / fmu.name
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                marker = 'name="h1" valueReference="1" causality="output" variability="continuous"'
                assert marker in text
                text = text.replace(marker, marker.replace("continuous", "fixed"))
                data = text.encode()
            dst.writestr(item, data)
    return out


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_fmpy_validate_reports_no_problem(which, request):
    fmu = request.getfixturevalue(which)
    result = _fmpy_validate(fmu)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "No problems found." in result.stdout


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_fmutool_check_reports_no_problem(which, request):
    fmu = request.getfixturevalue(which)
    version = "2" if which == "fmu2_path" else "3"
    result = _fmutool_check(fmu)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert f"This FMU seems to be compliant with FMI-{version}.0." in output
    assert f"No semantic error against the FMI-{version} standard." in output
    assert "ERROR" not in output


def test_checkers_catch_a_broken_description(fmu2_path, tmp_path):
    """Negative control: both tools do fail on an FMU with a forbidden combination."""
    broken = _broken_copy(fmu2_path, tmp_path)
    assert _fmpy_validate(broken).returncode != 0
    result = _fmutool_check(broken)
    assert result.returncode != 0
    assert "semantic error" in result.stdout + result.stderr


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_interface_names_and_units(which, request):
    md = read_model_description(request.getfixturevalue(which))
    variables = {v.name: v for v in md.modelVariables}
    units = {u.name for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.unit in units, f"{v.name} has no declared unit"
    for name in INPUTS:
        assert variables[name].causality == "input" and variables[name].unit == "m3/s"
    for name in ("qd1", "qd2", "qd3", "qd4"):
        assert float(variables[name].start) == 0.0
    for name in OUTPUTS:
        assert variables[name].causality == "output" and variables[name].unit == "m"
    for name in TUNABLES:
        assert (variables[name].causality, variables[name].variability) == (
            "parameter",
            "tunable",
        )
    for name in START_LEVELS:
        assert (variables[name].causality, variables[name].variability) == ("parameter", "fixed")
    assert variables["g"].variability == "constant" and float(variables["g"].start) == 9.81
    # Both interfaces, and the four levels are the continuous states.
    assert md.coSimulation is not None and md.modelExchange is not None
    assert [d.variable.name for d in md.derivatives] == [f"der({h})" for h in OUTPUTS]
    assert [d.variable.derivative.name for d in md.derivatives] == list(OUTPUTS)
    # No direct feedthrough: each output depends only on its own state.
    for out in md.outputs:
        assert [d.name for d in out.dependencies] == [out.variable.name]


def test_default_parameters_are_the_papers(fmu2_path):
    md = read_model_description(fmu2_path)
    from tests.fmus.fourtank_reference import PARAMETERS  # Alvarado et al. 2011, as in the paper

    start = {v.name: float(v.start) for v in md.modelVariables if v.start is not None}
    assert set(PARAMETERS) == set(TUNABLES)
    for name, value in PARAMETERS.items():
        assert start[name] == value


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_source_fmu_compiles_from_its_own_sources(which, request, tmp_path):
    """The sources inside the FMU build a working binary (source FMU)."""
    from cosim.core.build import fmi_headers_dir
    from tests.fmus.fourtank_run import LEVELS, Plant

    fmu = request.getfixturevalue(which)
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
        zf.extractall(tmp_path / "fmu")
    md = read_model_description(fmu)
    # FMI 2 lists the sources in the model description, FMI 3 in buildDescription.xml.
    assert ("sources/buildDescription.xml" in names) == md.fmiVersion.startswith("3")
    sources = [f for c in md.buildConfigurations for s in c.sourceFileSets for f in s.sourceFiles]
    platform = "linux64" if md.fmiVersion.startswith("2") else "x86_64-linux"
    assert sorted(sources) == sorted(["model.c", "instance.c", f"fmi{md.fmiVersion[0]}.c"])
    src = tmp_path / "fmu" / "sources"
    binary = tmp_path / "fmu" / "binaries" / platform / "FourTank.so"
    binary.unlink()
    cmd = ["gcc", "-std=c99", "-O2", "-shared", "-fPIC", f"-I{fmi_headers_dir()}"]
    cmd += ["-o", str(binary), *(str(src / s) for s in sources), "-lm"]
    subprocess.run(cmd, check=True, capture_output=True)
    rebuilt = tmp_path / "rebuilt.fmu"
    shutil.make_archive(str(rebuilt.with_suffix("")), "zip", tmp_path / "fmu")
    shutil.move(str(rebuilt.with_suffix(".zip")), rebuilt)
    plant = Plant(rebuilt, "cs")
    try:
        plant.initialize()
        plant.set(qa=0.0)
        plant.do_step(25.0)
        h = plant.get(*LEVELS)
        assert h[0] < 0.65 and h[3] < 0.6638294000727866
    finally:
        plant.close()


def test_fmi2_and_fmi3_descriptions_and_c_sources_agree(fmu2_path, fmu3_path):
    """One model, two descriptions: same variables, value references, starts and units, and
    the value-reference enum and name table in the C sources match them."""
    import re

    from cosim.core.build import SOURCE_DIR

    def table(path):
        md = read_model_description(path)
        return {
            v.name: (v.valueReference, v.causality, v.variability, v.start, v.unit)
            for v in md.modelVariables
        }

    fmi2, fmi3 = table(fmu2_path), table(fmu3_path)
    assert fmi3.pop("time")[:2] == (0, "independent")  # FMI 3 declares the independent variable
    assert fmi2 == fmi3

    header = (SOURCE_DIR / "model.h").read_text()
    enum = {name: int(vr) for name, vr in re.findall(r"\bVR_(\w+) = (\d+)", header)}
    for name, (vr, *_rest) in fmi2.items():
        key = name.replace("der(", "DER_").replace(")", "").upper()
        assert enum[key] == vr, name
    source = (SOURCE_DIR / "model.c").read_text()
    start = source.index("NAMES[N_VARIABLES] = {")
    names_block = source[start : source.index("};", start)]
    c_names = re.findall(r'"([^"]+)"', names_block)
    assert c_names[0] == "time"
    assert {name: i for i, name in enumerate(c_names) if i} == {n: v[0] for n, v in fmi2.items()}
