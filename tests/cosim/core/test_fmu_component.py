"""FmuComponent on the real four-tank FMUs (FMI 2/3, CS/ME), other exporters, and faults."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from cosim.core.errors import CosimError, FmuError, SimulationFailed
from cosim.core.fmu import FmuComponent
from cosim.core.fmu_archive import safe_extract
from cosim.core.isolated import IsolatedFmuComponent
from cosim.core.varmap import load as load_map

U = {"qa": 6.0e-4, "qb": 4.0e-4}


def simulate(comp: FmuComponent, steps: int = 40, dt: float = 25.0,
             changes: dict[int, tuple[str, float]] | None = None) -> list[dict[str, float]]:
    comp.setup(0.0)
    try:
        out = [comp.get_outputs()]
        for k in range(steps):
            if changes and k in changes:
                comp.set_parameter(*changes[k])
            comp.set_inputs(U)
            comp.step(k * dt, dt)
            out.append(comp.get_outputs())
        return out
    finally:
        comp.terminate()


def test_signals_by_name(fmu2_path: Path) -> None:
    comp = FmuComponent(fmu2_path)
    assert [s.name for s in comp.outputs] == ["h1", "h2", "h3", "h4"]
    assert {s.name for s in comp.inputs} == {"qa", "qb", "qd1", "qd2", "qd3", "qd4"}
    assert {s.unit for s in comp.outputs} == {"m"}
    assert {"S", "a1", "gamma_a", "gamma_b"} <= set(comp.tunables)
    assert "h1_start" in comp.settable(at_start=True)
    assert "h1_start" not in comp.settable()


def test_fmi2_and_fmi3_cs_agree_and_move(fmu2_path: Path, fmu3_path: Path) -> None:
    a = simulate(FmuComponent(fmu2_path))
    b = simulate(FmuComponent(fmu3_path))
    assert a == b  # same C model, same solver: bit-identical
    assert a[-1]["h4"] > a[0]["h4"] + 0.05  # qa = 6e-4 fills tank 4 over 1000 s


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_model_exchange_matches_co_simulation(which: str, request: pytest.FixtureRequest) -> None:
    path = request.getfixturevalue(which)
    cs = simulate(FmuComponent(path), changes={10: ("a1", 1.0e-4)})
    me = simulate(FmuComponent(path, interface="me"), changes={10: ("a1", 1.0e-4)})
    for x, y in zip(cs, me, strict=True):
        for name in x:
            assert y[name] == pytest.approx(x[name], abs=2e-6)


def test_tunable_parameter_changes_the_trajectory(fmu2_path: Path) -> None:
    base = simulate(FmuComponent(fmu2_path))
    smaller_outlet = simulate(FmuComponent(fmu2_path), changes={20: ("a1", 0.8e-4)})
    assert smaller_outlet[20] == base[20]
    assert smaller_outlet[-1]["h1"] > base[-1]["h1"] + 0.01
    assert smaller_outlet[-1]["h2"] == pytest.approx(base[-1]["h2"], abs=1e-12)


def test_start_values(fmu3_path: Path) -> None:
    comp = FmuComponent(fmu3_path, start_values={"h1_start": 1.25})
    comp.setup(0.0)
    try:
        assert comp.get_outputs()["h1"] == 1.25
    finally:
        comp.terminate()
        comp.terminate()  # idempotent


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_a_terminated_fmu_is_never_called_again(which: str,
                                                request: pytest.FixtureRequest) -> None:
    """After terminate() (the instance freed) reading, setting and stepping fail in one line
    naming why; the FMU is not called with the freed instance."""
    comp = FmuComponent(request.getfixturevalue(which))
    comp.setup(0.0)
    comp.get_outputs()
    comp.terminate()
    for call in (comp.get_outputs, lambda: comp.set_inputs(U), lambda: comp.step(0.0, 25.0)):
        with pytest.raises(SimulationFailed, match="after terminate") as info:
            call()
        assert "\n" not in str(info.value)


def test_fmu_error_becomes_simulation_failed_with_its_log(fmu2_path: Path) -> None:
    comp = FmuComponent(fmu2_path)
    comp.setup(0.0)
    try:
        comp.step(0.0, 25.0)
        with pytest.raises(SimulationFailed) as info:
            comp.step(0.0, 25.0)  # wrong communication point
    finally:
        comp.terminate()
    msg = str(info.value)
    assert msg.startswith("FourTank.fmu: doStep at t=0.0 failed:")
    assert "FMU log:" in msg and "\n" not in msg
    assert isinstance(info.value, FmuError)
    assert (info.value.function, info.value.status, info.value.fatal) == ("fmi2DoStep", 3, False)


@pytest.mark.parametrize(("status", "fatal"), [(3, False), (4, True), (None, False)])
def test_fmu_error_status_decides_whether_the_instance_is_freed(fmu3_path: Path, status,
                                                                fatal: bool) -> None:
    """The FMI status travels as an attribute (fmpy's FMICallException, our checks); after a
    fatal one the instance is neither terminated nor freed."""

    class CallFailed(Exception):
        function = "fmi3DoStep"

    exc = CallFailed("fmi3DoStep failed with status 4 (fatal).")  # the text is not read
    exc.status = status
    comp = FmuComponent(fmu3_path)
    err = comp._fail("doStep at t=0.0", exc)
    assert isinstance(err, FmuError) and err.status == status and comp._fatal is fatal
    assert str(err) == "FourTank3.fmu: doStep at t=0.0 failed: fmi3DoStep failed with " \
                       "status 4 (fatal)."


def test_unsafe_archives_are_rejected(tmp_path: Path) -> None:
    for i, bad in enumerate(["../evil.so", "/etc/evil", "a/../../x", "a\\b"]):
        path = tmp_path / f"bad{i}.fmu"
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("modelDescription.xml", "<x/>")
            zf.writestr(bad, "x")
        with pytest.raises(CosimError, match="unsafe path"):
            safe_extract(path, tmp_path / f"out{i}")
        assert not (tmp_path / "evil.so").exists()


def test_bad_files(tmp_path: Path, pyfmu_dir: Path) -> None:
    with pytest.raises(CosimError, match="FMU not found"):
        FmuComponent(tmp_path / "missing.fmu")
    junk = tmp_path / "junk.fmu"
    junk.write_text("not a zip")
    with pytest.raises(CosimError, match=r"junk.fmu: cannot read modelDescription.xml"):
        FmuComponent(junk)
    with pytest.raises(CosimError, match="no Model Exchange interface"):
        FmuComponent(pyfmu_dir / "Failing.fmu", interface="me")


def test_pythonfmu3_swap_in_with_map(pyfmu_dir: Path, fmu2_path: Path) -> None:
    vm = load_map(pyfmu_dir / "quadtank.map.toml")
    comp = FmuComponent(pyfmu_dir / "QuadTank.fmu", varmap=vm)
    assert {s.name for s in comp.inputs} == {"qa", "qb"}
    assert [s.name for s in comp.outputs] == ["h1", "h2", "L3", "L4"]
    comp.check_signals(["qa", "qb"], ["h1", "h2"])
    assert {"qa", "Fa", "gamma_a", "gammaA"} <= comp.settable()
    swapped = simulate(comp)
    ours = simulate(FmuComponent(fmu2_path))
    # l/min in, cm out, converted by the map: same physics, another integrator
    assert swapped[-1]["h1"] == pytest.approx(ours[-1]["h1"], abs=1e-5)
    assert swapped[-1]["L4"] == pytest.approx(100 * ours[-1]["h4"], abs=1e-3)


def test_isolated_matches_in_process(fmu2_path: Path) -> None:
    changes = {5: ("gamma_a", 0.35)}
    assert simulate(IsolatedFmuComponent(fmu2_path), steps=10, changes=changes) == \
        simulate(FmuComponent(fmu2_path), steps=10, changes=changes)


def test_isolated_segfault_is_a_clean_failure(pyfmu_dir: Path) -> None:
    comp = IsolatedFmuComponent(pyfmu_dir / "Segfault.fmu")
    comp.setup(0.0)
    try:
        for k in range(20):
            comp.set_inputs({"qa": 1e-4, "qb": 1e-4})
            comp.step(25.0 * k, 25.0)
        with pytest.raises(SimulationFailed, match=r"Segfault.fmu: doStep at t=500.0 failed: "
                                                   r"worker died \(signal 11"):
            comp.step(500.0, 25.0)
    finally:
        comp.terminate()


def test_python_exception_in_fmu_is_reported(pyfmu_dir: Path) -> None:
    comp = FmuComponent(pyfmu_dir / "Failing.fmu")
    comp.setup(0.0)
    try:
        for k in range(20):
            comp.step(25.0 * k, 25.0)
        with pytest.raises(SimulationFailed, match=r"doStep at t=500.0 failed: .*tank ruptured"):
            comp.step(500.0, 25.0)
    finally:
        comp.terminate()


def _rezip(src: Path, dst: Path, edit) -> Path:
    """Copy the FMU ``src`` to ``dst``, passing each member (name, bytes) through ``edit``
    (which returns the new pair, or None to drop the member)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            member = edit(info.filename, zin.read(info))
            if member is not None:
                zout.writestr(*member)
    return dst


def test_fmu_without_a_binary_for_this_platform_is_bad_input(tmp_path: Path,
                                                              fmu2_path: Path) -> None:
    def to_win64(name: str, data: bytes) -> tuple[str, bytes]:
        if name.startswith("binaries/linux64/"):
            return "binaries/win64/FourTank.dll", data
        return name, data

    fmu = _rezip(fmu2_path, tmp_path / "win.fmu", to_win64)
    for cls in (FmuComponent, IsolatedFmuComponent):
        comp = cls(fmu)
        with pytest.raises(CosimError, match=r"win\.fmu: no binary for this platform: "
                           r"'binaries/linux64/FourTank\.so' is missing \(it has binaries for: "
                           r"win64\)") as info:
            comp.setup(0.0)
        comp.terminate()
        assert not isinstance(info.value, SimulationFailed)


def test_fmu_with_a_corrupt_binary_is_bad_input(tmp_path: Path, fmu2_path: Path) -> None:
    def corrupt(name: str, data: bytes) -> tuple[str, bytes]:
        return name, (b"not a shared library" if name.endswith(".so") else data)

    fmu = _rezip(fmu2_path, tmp_path / "corrupt.fmu", corrupt)
    cwd = Path.cwd()
    comp = FmuComponent(fmu)
    with pytest.raises(CosimError, match=r"corrupt\.fmu: cannot load the FMU's binary: ") as info:
        comp.setup(0.0)
    comp.terminate()
    assert not isinstance(info.value, SimulationFailed)
    assert "\n" not in str(info.value) and "cosim-fmu-" not in str(info.value)
    assert Path.cwd() == cwd  # fmpy changes into the (now deleted) binaries folder


def test_a_folder_is_not_an_fmu(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match="is a folder, not an FMU file"):
        FmuComponent(tmp_path)


def test_isolated_worker_leaves_ctrl_c_to_the_parent(fmu2_path: Path) -> None:
    import os
    import signal
    import time

    comp = IsolatedFmuComponent(fmu2_path)
    comp.setup(0.0)
    try:
        pid = comp._worker.pid
        # a process group of its own: what the FMU sends to its group never reaches us
        assert os.getpgid(pid) == pid != os.getpgid(0)
        os.kill(pid, signal.SIGINT)
        time.sleep(0.2)
        comp.set_inputs(U)
        comp.step(0.0, 25.0)  # the worker is alive and serves requests
        assert comp._worker.pid == pid and 0.0 < comp.get_outputs()["h1"] < 2.0
    finally:
        comp.terminate()
    assert comp._worker is None
