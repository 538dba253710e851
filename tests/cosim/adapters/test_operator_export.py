"""The exported controller under the operator's actions (issue 61): the C step
(controllers/kernel/operator.c) and the controller FMU (its op.* inputs) give the Python
controller's inputs to the bit, in manual (the shadow's computed inputs too), with an input
out of service, under operator limits that ramp (an output's within the plan's room), with a
move limit (eq:move-constraint's rows in the kernel) and back in auto."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import cosim
from tests.fourtank_problem import PATH

#: (step, setting, value) of the replay, both laws (the paper's takes no output limit)
ACTIONS = [(2, "op.mode", 0.0), (2, "op.manual.qa", 3e-4), (8, "op.mode", 1.0),
           (14, "op.service.qb", 0.0), (18, "op.max.qa", 5e-4), (22, "op.service.qb", 1.0),
           (34, "op.min.qb", 4e-4)]
OUTPUT_ACTIONS = [(26, "op.max.h1", 1.2), (30, "op.min.h2", 0.7)]


@pytest.fixture(scope="module")
def problem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The four-tank's problem with a move limit on qa and a limit rate on h1."""
    text = PATH.read_text().replace('description = "pump a flow"',
                                    'description = "pump a flow"\nmax_move = 6e-5')
    text = text.replace('description = "level of tank 1"',
                        'description = "level of tank 1"\nlimit_rate = 0.01')
    path = tmp_path_factory.mktemp("opsx") / "problem.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("options", [{}, {"law": "paper", "governor": False}],
                         ids=["tracking", "paper"])
def test_the_compiled_step_replays_the_operators_actions(problem: Path, options: dict) -> None:
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
        operator_names,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(problem=problem, **options)
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), 2, 2)
    names = operator_names(design, ["qa", "qb"], ["h1", "h2"])
    assert ("op.max.h1" in names) is not options   # the tracking law's outputs only
    actions = ACTIONS + (OUTPUT_ACTIONS if not options else [])
    ctrl.setup(0.0)
    rng = np.random.default_rng(5)
    y = np.array([0.62, 0.71])
    statuses = set()
    for k in range(45):
        for _, name, value in (a for a in actions if a[0] == k):
            assert compiled.set_operator(names.index(name), value) is None
            ctrl.set(name, value)
        y = y + rng.normal(0, 2e-3, 2)
        ref = np.array([0.8, 0.9]) if k < 30 else np.array([1.2, 1.0])
        ctrl.set_inputs({"h1": y[0], "h2": y[1], "ref.h1": ref[0], "ref.h2": ref[1]})
        ctrl.step(25.0 * k, 25.0)
        out = compiled.step(y, ref)
        diag = ctrl.diagnostics()
        np.testing.assert_array_equal(out["u"], [ctrl.get_outputs()[n] for n in ("qa", "qb")])
        np.testing.assert_array_equal(out["computed"], [diag["computed.qa"],
                                                        diag["computed.qb"]])
        assert out["status"] == diag["status"]
        statuses.add(out["status"])
        if 3 <= k < 8:   # manual: the operator's qa, the shadow's own
            assert out["u"][0] == 3e-4 and out["computed"][0] != 3e-4
    assert 0 in statuses
    # refused alike: a limit that crosses the other
    assert compiled.set_operator(names.index("op.max.qb"), 3e-4) is not None
    with pytest.raises(cosim.CosimError, match="not below high"):
        ctrl.set("op.max.qb", 3e-4)
    compiled.close()


@pytest.mark.slow
def test_the_fmu_runs_an_operated_scenario_as_the_python_controller(
        problem: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "operated.csv"
    scenario.write_text("time,ref.h1,ref.h2,op.mode,op.manual.qa,op.service.qb,op.max.qa,"
                        "op.max.h1\n0,0.8,0.8,manual,3e-4,,,\n250,,,auto,,,,\n500,,,,,0,,\n"
                        "750,,,,,1,6e-4,1.2\n1000,,,,,,,0.6\n1250,,,,,,,\n")
    fmu = cosim.export_fmu(out=tmp_path / "Operated.fmu", problem=problem)
    py = cosim.run(scenario, problem=problem, out=tmp_path / "py", figure=False)
    run = cosim.run(scenario, controller=str(fmu), out=tmp_path / "fmu", figure=False)
    a, b = run.to_pandas(), py.to_pandas()
    for column in ("plant.qa", "plant.qb", "ctrl.qa", "ctrl.qb", "ctrl.status"):
        np.testing.assert_array_equal(a[column], b[column], err_msg=column)
    audit = [list(csv.DictReader((d / "operator.csv").open())) for d in (tmp_path / "fmu",
                                                                         tmp_path / "py")]
    assert [(r["what"], r["result"] == "accepted") for r in audit[0]] == \
        [(r["what"], r["result"] == "accepted") for r in audit[1]]
    assert [r["what"] for r in audit[0] if r["result"] != "accepted"] == ["op.max.h1"]
    assert run.summary["controller_summary"]["controller"] == "fmu"
