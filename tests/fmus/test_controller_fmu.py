"""The controller FMU (``cosim export-fmu``, ``fmus/controller/``) as other tools and masters see
it: compliant for ``fmpy validate`` and ``fmutool -check`` (FMI 2 and 3), units and default
experiment declared, several instances in one process independent, bad measurements and
steps handled as documented (docs: guide/controller-fmu.md), and plant + controller
connected by name in fmpy's own loop and in libcosim (an FMI engine not written here)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest

from tests.fmus.fourtank_run import LEVELS, Plant, libcosim_run

TS = 25.0
REFS = [(0, (0.65, 0.65)), (40, (1.3, 1.4)), (90, (0.9, 1.2))]   # (from step, (h1, h2))


def _ref(k: int) -> tuple[float, float]:
    return next(r for start, r in reversed(REFS) if k >= start)


@pytest.mark.parametrize("version", [2, 3])
def test_the_tools_that_judge_fmus_find_it_compliant(version: int,
                                                     controller_fmus: dict[int, Path]) -> None:
    path = controller_fmus[version]
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(path)) == []
    proc = subprocess.run([str(Path(sys.executable).with_name("fmutool")), "-input", str(path),
                           "-check"], capture_output=True, text=True, timeout=300, check=False)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert f"compliant with FMI-{version}.0" in log and "No semantic error" in log, log
    md = fmpy.read_model_description(str(path))
    assert float(md.defaultExperiment.stepSize) == TS
    units = {u.name: u for u in md.unitDefinitions}
    assert (units["m3/s"].baseUnit.m, units["m3/s"].baseUnit.s) == (3, -1)
    var = {v.name: v for v in md.modelVariables}
    assert [var[n].causality for n in ("h1", "h2", "ref.h1", "ref.h2")] == ["input"] * 4
    assert [var[n].causality for n in ("qa", "qb", "status", "pred.h1", "target.h2")
            ] == ["output"] * 5
    assert var["h1"].unit == var["target.h2"].unit == "m" and var["qa"].unit == "m3/s"
    assert float(var["qb"].max) == pytest.approx(1.11e-3)
    assert not md.coSimulation.canGetAndSetFMUstate
    beta = var["offset_filter"]
    assert (beta.causality, beta.variability, float(beta.start)) == ("parameter", "tunable", 0.3)


def _controller(path: Path, logger=None) -> Plant:
    ctrl = Plant(path, "cs", logger=logger)
    ctrl.initialize()
    return ctrl


def _control(ctrl: Plant, y: tuple[float, float], ref: tuple[float, float]) -> list[float]:
    ctrl.set(h1=y[0], h2=y[1], **{"ref.h1": ref[0], "ref.h2": ref[1]})
    ctrl.do_step(TS)
    return ctrl.get("qa", "qb", "status", "fallback")


def test_fmpys_loop_in_the_masters_order_is_the_master(controller_fmus: dict[int, Path],
                                                       fmu2_path: Path, tmp_path: Path) -> None:
    """fmpy's own loop (set y_k, controller doStep, read u_k, set u_k, plant doStep) gives
    the project master's run of the same plant and controller FMUs, to the bit."""
    import cosim

    steps = 140
    scenario = tmp_path / "steps.csv"
    scenario.write_text("time,ref.h1,ref.h2\n" + "".join(
        f"{k * TS:g},{r[0]},{r[1]}\n" for k, r in REFS) + f"{steps * TS:g},,\n")
    master = cosim.run(scenario, plant=fmu2_path, controller=str(controller_fmus[3]),
                       figure=False).to_pandas()
    plant, ctrl = Plant(fmu2_path, "cs"), _controller(controller_fmus[3])
    try:
        plant.initialize()
        u = np.empty((steps, 2))
        for k in range(steps):
            y = plant.get("h1", "h2")
            u[k] = _control(ctrl, (y[0], y[1]), _ref(k))[:2]
            plant.set(qa=u[k, 0], qb=u[k, 1])
            plant.do_step(TS)
    finally:
        plant.close()
        ctrl.close()
    np.testing.assert_array_equal(u, master[["ctrl.qa", "ctrl.qb"]].to_numpy()[:steps])


def test_libcosim_runs_plant_and_controller_connected(controller_fmus: dict[int, Path],
                                                      fmu2_path: Path) -> None:
    """libcosim steps the FMI 2 plant and controller connected by name (its fixed-step
    algorithm: every FMU steps from the values of the last communication point, so the plant
    applies u_k one sample later than in the project's master); fmpy stepping them the same
    way gives the same trajectory, to the bit."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    cpath, steps = controller_fmus[2], 60
    pvr = {v.name: v.valueReference for v in fmpy.read_model_description(
        str(fmu2_path)).modelVariables}
    cvr = {v.name: v.valueReference for v in fmpy.read_model_description(
        str(cpath)).modelVariables}
    execution = CosimExecution.from_step_size(step_size=int(TS * 1e9))
    p = execution.add_local_slave(CosimLocalSlave(fmu_path=str(fmu2_path.resolve()),
                                                  instance_name="plant"))
    c = execution.add_local_slave(CosimLocalSlave(fmu_path=str(cpath.resolve()),
                                                  instance_name="mpc"))
    for name in ("h1", "h2"):
        assert execution.connect_real_variables(p, pvr[name], c, cvr[name]) == 0
    for name in ("qa", "qb"):
        assert execution.connect_real_variables(c, cvr[name], p, pvr[name]) == 0
    override = CosimManipulator.create_override()
    execution.add_manipulator(override)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    h_cosim = np.empty((steps, 2))
    for k in range(steps):
        ref = _ref(k)
        override.slave_real_values(c, [cvr["ref.h1"], cvr["ref.h2"]], list(ref))
        assert execution.step()
        h_cosim[k] = observer.last_real_values(p, [pvr["h1"], pvr["h2"]])

    h = _jacobi(fmu2_path, cpath, _ref, steps)
    np.testing.assert_array_equal(h_cosim, h)
    assert abs(h[-1, 0] - 1.3) < 0.05   # and it tracks


def _jacobi(plant_path: Path, controller: Path, ref, steps: int,
            parameters: dict | None = None) -> np.ndarray:
    """The levels h1, h2 after each step of fmpy stepping both FMUs from the values of the
    last communication point (libcosim's fixed-step algorithm); ``parameters``: the
    controller's, set before its first step."""
    plant, ctrl = Plant(plant_path, "cs"), _controller(controller)
    ctrl.set(**(parameters or {}))
    try:
        plant.initialize()
        h = np.empty((steps, 2))
        for k in range(steps):
            y, u = plant.get("h1", "h2"), ctrl.get("qa", "qb")
            ctrl.set(h1=y[0], h2=y[1], **{"ref.h1": ref(k)[0], "ref.h2": ref(k)[1]})
            plant.set(qa=u[0], qb=u[1])
            ctrl.do_step(TS)
            plant.do_step(TS)
            h[k] = plant.get("h1", "h2")
    finally:
        plant.close()
        ctrl.close()
    return h


def test_an_ssp_file_of_plant_and_controller_runs_in_libcosim(
        controller_fmus: dict[int, Path], fmu2_path: Path, tmp_path: Path) -> None:
    """``cosim export-ssp``: libcosim loads the archive unchanged (connections, set-points,
    the controller's tuned weights, fixed step from the file) and runs the trajectory of fmpy's
    loop stepping the same way."""
    from cosim.cli import main

    ssp = tmp_path / "loop.ssp"
    tuned = {"R.qa": 0.05, "offset_weight.h1": 1e3}
    assert main(["export-ssp", "--plant", str(fmu2_path), "--controller",
                 str(controller_fmus[2]), "--setpoint", "ref.h1=1.3", "--setpoint",
                 "ref.h2=1.4", "--parameter", "R.qa=0.05", "--parameter",
                 "offset_weight.h1=1000", "--out", str(ssp), "--quiet"]) == 0
    steps = 50
    h_cosim = libcosim_run(ssp, fmu2_path, ["h1", "h2"], steps)
    h = _jacobi(fmu2_path, controller_fmus[2], lambda k: (1.3, 1.4), steps, tuned)
    np.testing.assert_array_equal(h_cosim, h)
    default = _jacobi(fmu2_path, controller_fmus[2], lambda k: (1.3, 1.4), steps)
    assert not np.array_equal(default, h)   # the tuned weights took effect


def test_two_instances_in_one_process_are_independent(controller_fmus: dict[int, Path]) -> None:
    """Two controllers stepped in turn give what each gives alone (the solver's state is the
    instance's, its tuned weights too: the first one's are set, the second keeps the
    design's)."""
    rng = np.random.default_rng(2)
    ys = [0.6 + 0.1 * np.cumsum(rng.normal(0, 0.02, (30, 2)), axis=0) + s for s in (0.0, 0.4)]
    tuned = {"R.qa": 0.05, "offset_weight.h1": 1e3, "du_weight.qb": 0.5}
    alone = []
    for y, weights in zip(ys, (tuned, {}), strict=True):
        ctrl = _controller(controller_fmus[3])
        ctrl.set(**weights)
        alone.append([_control(ctrl, tuple(v), (1.0, 1.1)) for v in y])
        ctrl.close()
    a, b = _controller(controller_fmus[3]), _controller(controller_fmus[3])
    a.set(**tuned)
    assert b.get("R.qa", "offset_weight.h1") == [0.01, 1e4]
    together: list[list] = [[], []]
    for k in range(30):
        together[0].append(_control(a, tuple(ys[0][k]), (1.0, 1.1)))
        together[1].append(_control(b, tuple(ys[1][k]), (1.0, 1.1)))
    a.close()
    b.close()
    assert together == alone
    assert alone[0] != alone[1]


def test_bad_measurements_and_steps_are_reported(controller_fmus: dict[int, Path]) -> None:
    """A NaN measurement holds the last inputs (status Warning, logged); a communication step
    that is not a multiple of Ts is refused with the reason logged; two samples in one step
    are two controller steps with the inputs held; the FMU state cannot be saved."""
    for version in (2, 3):
        log: list[tuple[int, str, str]] = []
        ctrl = _controller(controller_fmus[version],
                           logger=lambda s, c, m, log=log: log.append((s, c, m)))
        first = _control(ctrl, (0.62, 0.71), (1.0, 1.1))
        held = _control(ctrl, (float("nan"), 0.71), (1.0, 1.1))
        assert held[:2] == first[:2]
        assert any(s == 1 and c == "logStatusWarning" and "not finite" in m
                   for s, c, m in log), log
        with pytest.raises(Exception, match=r"FMUState|FMUstate"):
            ctrl.fmu.getFMUState()
        assert any("cannot save its state" in m for _, _, m in log), log
        with pytest.raises(Exception, match=r"DoStep|doStep"):
            ctrl.fmu.doStep(currentCommunicationPoint=ctrl.time, communicationStepSize=10.0)
        assert any("not a multiple of the controller's sample time 25" in m
                   for _, _, m in log), log
        ctrl.initialized = False   # in the Error state: only freed (FMI)
        ctrl.close()

    one, two = _controller(controller_fmus[3]), _controller(controller_fmus[3])
    for ctrl in (one, two):
        _control(ctrl, (0.62, 0.71), (1.0, 1.1))
    _control(one, (0.63, 0.72), (1.0, 1.1))
    _control(one, (0.63, 0.72), (1.0, 1.1))
    two.set(h1=0.63, h2=0.72)
    two.do_step(2 * TS)
    assert one.get("qa", "qb", "status") == two.get("qa", "qb", "status")
    one.close()
    two.close()


@pytest.mark.parametrize("version", [2, 3])
def test_a_refused_set_sets_nothing_and_a_step_is_bounded(
        version: int, controller_fmus: dict[int, Path]) -> None:
    """Setting several values is all or nothing: one the FMU refuses (``R.qb = 0``) leaves
    the values before it in the same call (``R.qa``, ``offset_filter``) as they were, with
    the reason logged; and a communication step of more than ``CTL_MAX_STEPS_PER_CALL``
    (1000) samples is refused before it runs, with the reason logged."""
    log: list[tuple[int, str, str]] = []
    ctrl = _controller(controller_fmus[version],
                       logger=lambda s, c, m, log=log: log.append((s, c, m)))
    before = ctrl.get("R.qa", "offset_filter", "R.qb")
    with pytest.raises(Exception, match=r"SetReal|SetFloat64"):
        ctrl.set(**{"R.qa": 0.5, "offset_filter": 0.9, "R.qb": 0.0})
    assert ctrl.get("R.qa", "offset_filter", "R.qb") == before
    assert any("cannot set R.qb = 0" in m and "no value of this call is set" in m
               for _, _, m in log), log
    _control(ctrl, (0.62, 0.71), (1.0, 1.1))
    for samples in (1001, 1e9):   # refused before any step (unbounded, 1e9 runs for days)
        log.clear()
        with pytest.raises(Exception, match=r"DoStep|doStep"):
            ctrl.fmu.doStep(currentCommunicationPoint=ctrl.time,
                            communicationStepSize=samples * TS)
        assert any("at most 1000 controller steps per doStep" in m for _, _, m in log), log
        ctrl.initialized = False   # in the Error state: only freed (FMI)
        ctrl.close()
        ctrl = _controller(controller_fmus[version],
                           logger=lambda s, c, m, log=log: log.append((s, c, m)))
    assert _control(ctrl, (0.62, 0.71), (1.0, 1.1))[2] == 0   # status optimal
    ctrl.close()


def test_every_warning_of_a_step_is_logged(tmp_path: Path) -> None:
    """A step raising two warnings logs both, one line each, most serious first: the paper's
    law's FMU at a first measured output no input in the box reaches and a set-point outside
    the theory (the closest admissible one taken), FMI 2 and 3."""
    import cosim

    for version in (2, 3):
        fmu = cosim.export_fmu(out=tmp_path / f"Paper{version}.fmu", fmi=version,
                               options={"law": "paper", "governor": False})
        log: list[tuple[int, str, str]] = []
        ctrl = _controller(fmu, logger=lambda s, c, m, log=log: log.append((s, c, m)))
        _control(ctrl, (1.9, 0.05), (3.0, 0.3))
        warnings = [m for s, c, m in log if s == 1 and c == "logStatusWarning"]
        assert len(warnings) == 2, log
        assert "set-point refused" in warnings[0], warnings
        assert "no equilibrium output the inputs' box reaches" in warnings[1], warnings
        ctrl.close()


def test_the_levels_it_reads_are_the_plants(controller_fmus: dict[int, Path]) -> None:
    """Every measured output of the controller is an output of the plant, with its unit."""
    plant = {v.name: v for v in fmpy.read_model_description(
        str(Path(__file__).resolve().parents[2] / "fmus" / "FourTank.fmu")).modelVariables}
    ctrl = fmpy.read_model_description(str(controller_fmus[3])).modelVariables
    for v in ctrl:
        if v.causality == "input" and not v.name.startswith(("ref.", "op.")):
            assert v.name in LEVELS and plant[v.name].causality == "output"
            assert v.unit == plant[v.name].unit
        if v.name in ("qa", "qb"):
            assert plant[v.name].causality == "input"


@pytest.mark.parametrize("law", ["tracking", "paper"])
def test_it_never_allocates_after_instantiation(law: str, controller_fmus: dict[int, Path],
                                                tmp_path: Path) -> None:
    """200 steps (a set-point step, one NaN measurement) of the FMI 3 controller, the tracking
    law's and the paper's with its governor, from a C host whose malloc, calloc, realloc and
    posix_memalign count their calls: none while stepping (and some at instantiation, so the
    counting works)."""
    import shutil
    import zipfile

    import cosim

    if shutil.which("gcc") is None:
        pytest.skip("gcc not found")
    harness = tmp_path / "harness"
    proc = subprocess.run(["gcc", "-O1", f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                           str(Path(__file__).with_name("alloc_harness.c")), "-o",
                           str(harness), "-ldl", "-lm"], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    path = (controller_fmus[3] if law == "tracking"
            else cosim.export_fmu(out=tmp_path / "Paper.fmu", options={"law": "paper"}))
    with zipfile.ZipFile(path) as zf:
        zf.extractall(tmp_path / "fmu")
    md = fmpy.read_model_description(str(path))
    lib = tmp_path / "fmu" / "binaries" / "x86_64-linux" / f"{path.stem}.so"
    proc = subprocess.run([str(harness), str(lib), md.instantiationToken, str(TS),
                           f"{tmp_path / 'fmu' / 'resources'}/"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "allocations while stepping: 0, status ok" in proc.stdout, proc.stdout
    at_start = int(re.search(r"allocations at instantiation: (\d+)", proc.stdout).group(1))
    assert at_start >= 2, proc.stdout


def test_its_sources_build_as_its_build_description_says(controller_fmus: dict[int, Path],
                                                         tmp_path: Path) -> None:
    """A source FMU: ``sources/`` with the files and defines of ``buildDescription.xml``
    compiles as C99 (``-std=c99 -pedantic``) against the FMI headers, and the rebuilt binary
    controls (the first steps solved, the inputs in their boxes)."""
    import shutil
    import xml.etree.ElementTree as ET
    import zipfile

    if shutil.which("gcc") is None:
        pytest.skip("gcc not found")
    path = controller_fmus[3]
    src = tmp_path / "fmu"
    with zipfile.ZipFile(path) as zf:
        zf.extractall(src)
    config = ET.parse(src / "sources" / "buildDescription.xml").getroot().find(
        "BuildConfiguration/SourceFileSet")
    assert config is not None and config.get("language") == "C99"
    files = [str(src / "sources" / f.get("name")) for f in config.iter("SourceFile")]
    defines = [f"-D{d.get('name')}={d.get('value') or ''}"
               for d in config.iter("PreprocessorDefinition")]
    binary = src / "binaries" / "x86_64-linux" / f"{path.stem}.so"
    binary.unlink()
    proc = subprocess.run(["gcc", "-std=c99", "-pedantic", "-O2", "-fPIC", "-shared", *defines,
                           f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                           f"-I{src / 'sources'}", "-o", str(binary), *files, "-lm"],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rebuilt = tmp_path / path.name
    shutil.make_archive(str(rebuilt.with_suffix("")), "zip", src)
    rebuilt.with_suffix(".zip").rename(rebuilt)
    ctrl = _controller(rebuilt)
    for _ in range(5):
        qa, qb, status, _ = _control(ctrl, (0.62, 0.71), (0.8, 0.9))
        assert status == 0 and 0.0 <= qa <= 9.05e-4 and 0.0 <= qb <= 1.11e-3
    ctrl.close()


@pytest.mark.parametrize("version", [2, 3])
def test_reset_gives_a_fresh_controller(version: int, controller_fmus: dict[int, Path]) -> None:
    """``fmi2Reset`` / ``fmi3Reset`` after some steps, initialised again: the same inputs as
    the first time (observer, plan and warm start forgotten; the parameter set again)."""
    ctrl = _controller(controller_fmus[version])
    ctrl.set(offset_filter=0.7)
    first = [_control(ctrl, (0.6 + 0.01 * k, 0.7), (1.0, 1.1)) for k in range(5)]
    ctrl.fmu.reset()
    ctrl.time = 0.0
    ctrl.initialize(offset_filter=0.7)
    assert [_control(ctrl, (0.6 + 0.01 * k, 0.7), (1.0, 1.1)) for k in range(5)] == first
    ctrl.close()
