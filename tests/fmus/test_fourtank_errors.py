"""Bad calls get an FMI error status and a logged message, never a crash (FMI 2 and 3)."""

from __future__ import annotations

import ctypes
import math

import pytest
from fmpy.fmi1 import FMICallException

from tests.fmus.fourtank_run import LEVELS, Plant, fmi2_callbacks

VERSIONS = ("fmu2", "fmu3")


@pytest.fixture(params=VERSIONS)
def fmu_path(request, fmu2_path, fmu3_path):
    return fmu2_path if request.param == "fmu2" else fmu3_path


class Log:
    """Collects (status, category, message) from the FMU's logger callback."""

    def __init__(self) -> None:
        self.records: list[tuple[int, str, str]] = []

    def __call__(self, status: int, category: str, message: str) -> None:
        self.records.append((status, category, message))

    def last_error(self) -> str:
        errors = [m for s, _, m in self.records if s == 3]
        assert errors, f"no error logged (got {self.records})"
        return errors[-1]


@pytest.fixture
def plant(fmu_path):
    log = Log()
    p = Plant(fmu_path, "cs", logger=log)
    p.log = log
    yield p
    p.close()


def _initialized(plant):
    plant.initialize()
    return plant


def test_negative_step_size(plant):
    _initialized(plant)
    with pytest.raises(FMICallException, match="error"):
        plant.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=-1.0)
    assert "communicationStepSize" in plant.log.last_error()
    assert "-1" in plant.log.last_error()
    # The instance is still usable afterwards.
    plant.do_step(25.0)
    assert all(h > 0 for h in plant.get(*LEVELS))


def test_nan_step_size_and_wrong_communication_point(plant):
    _initialized(plant)
    with pytest.raises(FMICallException):
        plant.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=math.nan)
    assert "communicationStepSize" in plant.log.last_error()
    with pytest.raises(FMICallException):
        plant.fmu.doStep(currentCommunicationPoint=100.0, communicationStepSize=25.0)
    assert "currentCommunicationPoint" in plant.log.last_error()


@pytest.mark.parametrize("name", ["qa", "qb", "qd1", "qd4", "S", "a2", "gamma_b"])
def test_nan_input_or_parameter(plant, name):
    _initialized(plant)
    before = plant.get(name)[0]
    with pytest.raises(FMICallException):
        plant.set(**{name: math.nan})
    msg = plant.log.last_error()
    assert name in msg and "finite" in msg
    assert plant.get(name)[0] == before  # value left unchanged
    with pytest.raises(FMICallException):
        plant.set(**{name: math.inf})


@pytest.mark.parametrize("name", ["h1_start", "h4_start"])
def test_fixed_parameter_after_initialisation(plant, name):
    plant.set(**{name: 0.3})  # allowed before initialisation
    _initialized(plant)
    assert plant.get(name)[0] == 0.3
    with pytest.raises(FMICallException):
        plant.set(**{name: 0.5})
    msg = plant.log.last_error()
    assert name in msg and "fixed" in msg
    assert plant.get(name)[0] == 0.3


@pytest.mark.parametrize(
    ("name", "value", "why"),
    [
        ("g", 9.0, "constant"),
        ("h1", 0.5, "output"),
        ("der(h2)", 0.0, "derivative"),
        ("S", 0.0, "> 0"),
        ("a3", -1e-5, ">= 0"),
        ("gamma_a", 1.5, "[0, 1]"),
        ("h2_start", -0.1, ">= 0"),
    ],
)
def test_refused_values(plant, name, value, why):
    with pytest.raises(FMICallException):
        plant.set(**{name: value})
    msg = plant.log.last_error()
    assert name in msg and why in msg


def test_a_refused_value_leaves_the_whole_call_unset(plant):
    """Setting several values is all or nothing: the values before the refused one in the
    same call are put back (in any state the call is allowed in)."""
    for initialized in (False, True):
        if initialized:
            _initialized(plant)
        before = plant.get("qa", "S", "gamma_a")
        with pytest.raises(FMICallException):
            plant.set(qa=5e-4, S=0.07, gamma_a=1.5)
        assert plant.get("qa", "S", "gamma_a") == before
        assert "no value of this call is set" in plant.log.last_error()


def test_tunable_parameter_after_initialisation_is_accepted(plant):
    _initialized(plant)
    plant.set(S=0.07, a1=1.2e-4, gamma_a=0.25)
    assert plant.get("S", "a1", "gamma_a") == [0.07, 1.2e-4, 0.25]
    assert not [r for r in plant.log.records if r[0] >= 3]


def test_unknown_value_reference(plant):
    _initialized(plant)
    get = plant.fmu.getReal if plant.version == 2 else plant.fmu.getFloat64
    setter = plant.fmu.setReal if plant.version == 2 else plant.fmu.setFloat64
    with pytest.raises(FMICallException):
        get([999])
    assert "unknown value reference 999" in plant.log.last_error()
    with pytest.raises(FMICallException):
        setter([12345], [1.0])
    assert "unknown value reference 12345" in plant.log.last_error()


def test_null_pointers(plant):
    """NULL arrays with a non-zero length are refused, not dereferenced."""
    _initialized(plant)
    fmu = plant.fmu
    if plant.version == 2:
        calls = [
            lambda: fmu.fmi2GetReal(fmu.component, None, 1, None),
            lambda: fmu.fmi2SetReal(fmu.component, None, 2, None),
            lambda: fmu.fmi2GetFMUstate(fmu.component, None),
        ]
    else:
        calls = [
            lambda: fmu.fmi3GetFloat64(fmu.component, None, 1, None, 1),
            lambda: fmu.fmi3DoStep(fmu.component, 0.0, 25.0, False, None, None, None, None),
            lambda: fmu.fmi3GetFMUState(fmu.component, None),
        ]
    for call in calls:
        with pytest.raises(FMICallException, match="status 3"):
            call()
        assert "must not be NULL" in plant.log.last_error()


def test_null_instance_is_refused(fmu_path):
    p = Plant(fmu_path, "cs")
    try:
        p.initialize()
        with pytest.raises(FMICallException, match="status 3"):
            if p.version == 2:
                p.fmu.fmi2DoStep(None, 0.0, 25.0, False)
            else:
                p.fmu.fmi3EnterStepMode(None)
    finally:
        p.close()


def test_calls_out_of_order(plant):
    with pytest.raises(FMICallException):
        plant.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=25.0)
    assert "must not be called in Instantiated" in plant.log.last_error()


def test_wrong_instantiation_token(fmu_path):
    log = Log()
    p = Plant(fmu_path, "cs")  # keeps the shared library loaded
    try:
        lib = p.fmu.dll
        if p.version == 2:
            callbacks = fmi2_callbacks(log)
            fn = lib.fmi2Instantiate
            fn.restype = ctypes.c_void_p
            c = fn(b"x", 1, b"{wrong}", None, ctypes.byref(callbacks), 0, 0)
        else:
            from fmpy.fmi3 import fmi3IntermediateUpdateCallback, fmi3LogMessageCallback

            callback = fmi3LogMessageCallback(
                lambda env, status, cat, msg: log(status, cat.decode(), msg.decode())
            )
            fn = lib.fmi3InstantiateCoSimulation
            fn.restype = ctypes.c_void_p
            c = fn(
                b"x",
                b"{wrong}",
                None,
                0,
                0,
                0,
                0,
                None,
                0,
                None,
                callback,
                fmi3IntermediateUpdateCallback(),
            )
        assert c is None
        assert "{wrong}" in log.last_error()
    finally:
        p.close()


def test_model_exchange_bad_states(fmu_path):
    log = Log()
    p = Plant(fmu_path, "me", logger=log)
    try:
        p.initialize()
        fmu = p.fmu
        set_states = getattr(fmu, f"fmi{p.version}SetContinuousStates")
        fmu.enterContinuousTimeMode()
        x = (ctypes.c_double * 4)(0.1, math.nan, 0.3, 0.4)
        with pytest.raises(FMICallException, match="status 3"):
            set_states(fmu.component, x, 4)
        assert "h2 must be finite" in log.last_error()
        with pytest.raises(FMICallException, match="status 3"):
            set_states(fmu.component, x, 3)
        assert "4 continuous states" in log.last_error()
        # Negative levels handed in by a solver are projected to the physical domain.
        fmu.setContinuousStates((ctypes.c_double * 4)(-1e-9, 0.2, 0.3, 0.4), 4)
        assert p.get("h1") == [0.0]
    finally:
        p.close()
