"""A controller FMU of a plant whose problem renames and converts, outside the Python
controller: ``cosim export-ssp`` connects each signal to the plant variable its problem names,
through the map between their units, and a measured disturbance reaches plant and controller
as one value (libcosim runs the file as fmpy's loop does with the same values); ``cosim run``
binds the plant through the variables the FMU records, without the problem."""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.core.fmu_archive import plant_variables
from tests import example_builds
from tests.fmus.fourtank_run import Plant, libcosim_run
from tests.heater_problem import heater_doc
from tests.toml_text import toml_text

ROOT = Path(__file__).resolve().parents[3]


def _kelvin_problem() -> str:
    """The example heater in kelvin, its power named ``power`` and its ambient temperature
    measured (no rate)."""
    doc = heater_doc()
    doc["problem"]["name"] = "heater_kelvin"
    doc["inputs.power"] = {**doc.pop("inputs.P"), "variable": "P"}
    doc["outputs.T"] |= {"unit": "K", "min": 288.15, "max": 353.15}
    del doc["disturbances.T_in"]["rate"]
    doc["disturbances.T_in"] |= {"unit": "K", "min": 278.15, "max": 308.15}
    return toml_text(doc)


#: the example heater in kelvin, its ambient temperature measured under another name
PROBLEM = _kelvin_problem()
SSD = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
SSC = "{http://ssp-standard.org/SSP1/SystemStructureCommon}"
SSV = "{http://ssp-standard.org/SSP1/SystemStructureParameterValues}"


@pytest.fixture(scope="module")
def kelvin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The heater FMU (degC), a briefly trained model of it in kelvin and its controller
    FMUs (FMI 2 and 3)."""
    folder = tmp_path_factory.mktemp("ssp_kelvin")
    fmu = example_builds.build("heater", folder)
    problem = folder / "heater_kelvin.toml"
    problem.write_text(PROBLEM)
    data, model = folder / "data.csv", folder / "gru.json"
    assert main(["generate-data", "--plant", str(fmu), "--problem", str(problem), "--steps",
                 "1500", "--out", str(data), "--quiet"]) == 0
    assert main(["train", str(data), "--epochs", "5", "--n", "4", "--out", str(model),
                 "--quiet"]) == 0
    out = {"plant": fmu, "model": model}
    for version in (2, 3):
        out[f"c{version}"] = folder / f"Controller{version}.fmu"
        assert main(["export-fmu", str(model), "--fmi", str(version), "--out",
                     str(out[f"c{version}"]), "--quiet"]) == 0
    return out


def test_the_controller_fmu_records_its_plant_variables(kelvin: dict[str, Path]) -> None:
    from fmpy.validation import validate_fmu

    for version in (2, 3):
        assert plant_variables(kelvin[f"c{version}"]) == {
            "T": "T", "power": "P", "dist.T_in": "T_amb"}
        assert validate_fmu(str(kelvin[f"c{version}"])) == []


def _ssd(path: Path) -> ET.Element:
    with zipfile.ZipFile(path) as zf:
        return ET.fromstring(zf.read("SystemStructure.ssd"))


def test_libcosim_runs_the_ssp_with_units_converted_and_one_disturbance(
        kelvin: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ssp = tmp_path / "loop.ssp"
    assert main(["export-ssp", "--plant", str(kelvin["plant"]), "--controller",
                 str(kelvin["c2"]), "--setpoint", "dist.T_in=285.15", "--setpoint",
                 "ref.T=323.15", "--out", str(ssp)]) == 0
    assert "dist.T_in = plant.T_amb" in capsys.readouterr().out
    root = _ssd(ssp)
    links = {(c.get("startConnector"), c.get("endConnector")): c
             for c in root.iter(f"{SSD}Connection")}
    assert set(links) == {("T", "T"), ("power", "P")}
    assert links[("power", "P")].find(f"{SSC}LinearTransformation") is None   # W to W
    kelvin_of = links[("T", "T")].find(f"{SSC}LinearTransformation")
    assert kelvin_of is not None and links[("T", "T")].get("suppressUnitConversion") == "true"
    factor, offset = float(kelvin_of.get("factor")), float(kelvin_of.get("offset"))
    assert factor == pytest.approx(1.0) and offset == pytest.approx(273.15)
    plant_values = {p.get("name"): float(p.find(f"{SSV}Real").get("value"))
                    for c in root.iter(f"{SSD}Component") if c.get("name") == "plant"
                    for p in c.iter(f"{SSV}Parameter")}
    assert plant_values == {"T_amb": pytest.approx(12.0)}   # 285.15 K in the plant's degC

    steps = 40
    cosim = libcosim_run(ssp, kelvin["plant"], ["T", "P", "T_amb"], steps)

    # fmpy's loop stepping both from the last communication point (libcosim's algorithm)
    plant, ctrl = Plant(kelvin["plant"], "cs"), Plant(kelvin["c2"], "cs")
    try:
        plant.initialize(T_amb=plant_values["T_amb"])
        ctrl.initialize(**{"dist.T_in": 285.15, "ref.T": 323.15})
        loop = np.empty((steps, 3))
        for k in range(steps):
            (y,), (u,) = plant.get("T"), ctrl.get("power")
            ctrl.set(T=factor * y + offset)
            plant.set(P=u)
            ctrl.do_step(20.0)
            plant.do_step(20.0)
            loop[k] = plant.get("T", "P", "T_amb")
    finally:
        plant.close()
        ctrl.close()
    np.testing.assert_array_equal(cosim, loop)
    assert np.all(cosim[:, 2] == plant_values["T_amb"])
    assert np.ptp(cosim[:, 1]) > 0   # the controller moved the power


def test_a_disturbance_the_plant_lacks_is_refused(kelvin: dict[str, Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The four-tank plant has neither the heater's signals nor its ambient temperature."""
    code = main(["export-ssp", "--controller", str(kelvin["c3"]), "--out",
                 str(tmp_path / "x.ssp")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert "measured disturbance 'dist.T_in' is the plant's variable 'T_amb'" in err
    assert not (tmp_path / "x.ssp").exists()


def test_cosim_run_binds_the_plant_through_the_variables_the_fmu_records(
        kelvin: dict[str, Path], tmp_path: Path) -> None:
    """Without --problem, the controller FMU's record renames ``power`` to the plant's ``P``
    and ``T_in`` to ``T_amb`` and converts kelvin to the plant's degC: the Python
    controller's inputs to the bit."""
    import cosim

    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.T,dist.T_in\n0,318.15,293.15\n600,328.15,\n1200,,283.15\n"
                        "1800,,\n")
    fmu = cosim.run(scenario, plant=kelvin["plant"], controller=str(kelvin["c3"]),
                    figure=False).to_pandas()
    py = cosim.run(scenario, plant=kelvin["plant"], model=kelvin["model"],
                   figure=False).to_pandas()
    np.testing.assert_array_equal(fmu["ctrl.power"].to_numpy(), py["ctrl.power"].to_numpy())
    np.testing.assert_array_equal(fmu["plant.T"].to_numpy(), py["plant.T"].to_numpy())
    assert fmu["plant.T"].iloc[-1] > 300.0   # recorded in the problem's kelvin
