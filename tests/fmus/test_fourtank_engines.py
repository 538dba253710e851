"""The plant FMUs in other engines and interfaces: Model Exchange through fmpy's CVode,
and the FMI 2 FMU in libcosim (an FMI engine not written here)."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest

from tests.fmus.fourtank_reference import random_inputs
from tests.fmus.fourtank_run import LEVELS, run_cs

TS = 25.0


def _input_signal(u: np.ndarray) -> np.ndarray:
    """fmpy input table holding u[k] over [k Ts, (k+1) Ts] (repeated times = steps)."""
    names = ("qa", "qb", "qd1", "qd2", "qd3", "qd4")
    rows = []
    for k, (qa, qb) in enumerate(u):
        rows.append((k * TS, qa, qb, 0.0, 0.0, 0.0, 0.0))
        rows.append(((k + 1) * TS, qa, qb, 0.0, 0.0, 0.0, 0.0))
    return np.array(rows, dtype=[("time", float)] + [(n, float) for n in names])


def _run_me(path, u: np.ndarray) -> np.ndarray:
    res = fmpy.simulate_fmu(
        path,
        fmi_type="ModelExchange",
        solver="CVode",
        relative_tolerance=1e-10,
        input=_input_signal(u),
        stop_time=TS * len(u),
        output_interval=TS,
        output=list(LEVELS),
    )
    y = np.empty((len(u) + 1, 4))
    for k in range(len(u) + 1):
        # At an input event fmpy records the state before and after: take the last row.
        row = np.flatnonzero(np.isclose(res["time"], k * TS, rtol=0, atol=1e-6))[-1]
        y[k] = [res[name][row] for name in LEVELS]
    return y


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_model_exchange_cvode_matches_co_simulation(which, request):
    path = request.getfixturevalue(which)
    u = random_inputs(400, seed=3)  # includes pumps-off holds that empty tanks
    y_me = _run_me(path, u)
    y_cs = run_cs(path, u)
    assert np.abs(y_me - y_cs).max() < 1e-6
    assert (y_cs == 0.0).any(), "the sequence should drain a tank to empty"
    assert y_me.min() >= 0.0


def test_fmi3_co_simulation_matches_fmi2(fmu2_path, fmu3_path):
    u = random_inputs(500, seed=8)
    np.testing.assert_allclose(run_cs(fmu3_path, u), run_cs(fmu2_path, u), rtol=0, atol=1e-12)


def test_libcosim_matches_fmpy(fmu2_path):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    md = fmpy.read_model_description(fmu2_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    u = random_inputs(300, seed=7)

    execution = CosimExecution.from_step_size(step_size=int(TS * 1e9))  # nanoseconds
    slave = execution.add_local_slave(
        CosimLocalSlave(fmu_path=str(fmu2_path.resolve()), instance_name="plant")
    )
    override = CosimManipulator.create_override()
    execution.add_manipulator(override)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    level_refs = [vr[name] for name in LEVELS]
    y = np.empty((len(u), 4))
    for k, (qa, qb) in enumerate(u):
        override.slave_real_values(slave, [vr["qa"], vr["qb"]], [float(qa), float(qb)])
        assert execution.step(1)
        y[k] = observer.last_real_values(slave, level_refs)
    status = execution.status()
    assert status.current_time == int(TS * 1e9) * len(u)

    y_fmpy = run_cs(fmu2_path, u)[1:]
    assert np.abs(y - y_fmpy).max() <= 1e-9
    assert np.ptp(y, axis=0).min() > 0.05  # the levels really moved
