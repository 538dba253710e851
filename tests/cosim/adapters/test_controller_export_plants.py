"""The controller FMU of plants other than the four tanks gives the Python controller's inputs:
the example CSTR and mixing tank (pythonfmu FMUs, with GRU models of their problems whose
first measured outputs no input in the box reaches), one input and two outputs (the governor
along the surface of equilibrium outputs); one binary serves every model of its dimensions,
and a damaged or edited data file is refused at instantiation."""

from __future__ import annotations

import json
from pathlib import Path

import fmpy
import numpy as np
import pytest

import cosim
from tests.cosim.adapters.export_cases import (
    GOVERNED,
    PAPER_LAW,
    example_case,
    replayed,
    same_inputs,
)

#: The example plants' input boxes.
CSTR = {"F": (50.0, 150.0), "Tc": (290.0, 350.0)}
MIXING = {"Fh": (0.3, 1.5), "Fc": (0.3, 1.5), "Fw": (0.3, 1.5)}
#: What a case reaches.
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

    plant, model, steps_csv = example_case(tmp_path, plant_name, seed, steps)
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
    same_inputs(run, py, boxes)
    if FAILS in reaches:
        assert set(py.to_pandas()["ctrl.status"]) - {0.0}, "the case should reach " + FAILS
    if options == GOVERNED:
        assert summary["governor_steps"] > 0
    rejections = summary.get("setpoint_rejections", [])
    assert any("is not reachable with inputs inside" in r for r in rejections) is (
        UNREACHABLE in reaches), rejections


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
    fractions = {ctrl.mpc.law.lam for _ in replayed(ctrl, compiled, refs)}
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
    same_inputs(cosim.run(steps, plant=plant, controller=str(fmu), figure=False), py,
                {"qa": (0.0, 9.05e-4)})
    assert min(set(py.to_pandas()["ctrl.governor_lambda"]) - {0.0}) < 0.5


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
        plant, model, steps_csv = example_case(tmp_path / f"m{seed}", "cstr", seed, steps)
        fmus[seed] = tmp_path / f"Controller{seed}.fmu"
        assert main(["export-fmu", str(model), "--scenario", str(steps_csv), "--out",
                     str(fmus[seed]), "--quiet"]) == 0
        with zipfile.ZipFile(fmus[seed]) as zf:
            archives[seed] = {n: zf.read(n) for n in zf.namelist()}
        py = cosim.run(steps_csv, plant=plant, model=model, figure=False)
        run = cosim.run(steps_csv, plant=plant, controller=str(fmus[seed]), figure=False)
        same_inputs(run, py, CSTR)
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
