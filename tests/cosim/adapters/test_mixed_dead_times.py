"""Inputs with different dead times (issue 46): the robust MPC predicts over the shortest, fixes
the FHOCP's first inputs of a slower input to those it applied, and applies each input's own
stage; the exported C step does the same, to the bit.

The plant is the GRU model itself with the delays of its problem (``model:FILE``: the
prediction is exact), the shipped four-tank model whose pump ``qb`` acts six samples after
``qa`` (``delay = 0`` and ``6``): the controller that knows it is compared with ones that
take one dead time for both inputs.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.cli import main
from tests.cosim.adapters.export_cases import replayed

ROOT = Path(__file__).resolve().parents[3]
SCENARIO = ROOT / "scenarios" / "paper_steps.csv"


def delayed_model(folder: Path, name: str, delays: tuple[int, int]) -> Path:
    """The shipped four-tank model with ``delays`` on (qa, qb), as ``folder/name.json``
    (``benchmarks/mixed_dead_times.py`` uses it too)."""
    from controllers.model import DEFAULT_MODEL

    doc = json.loads(Path(DEFAULT_MODEL).read_text())
    for entry, k in zip(doc["problem"]["inputs"], delays, strict=True):
        entry["delay"] = k
    path = folder / f"{name}.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("mixed")
    return {name: delayed_model(folder, name, delays) for name, delays in (
        ("mixed", (0, 6)), ("none", (0, 0)), ("both", (6, 6)), ("short", (1, 3)))}


def _iae(run: cosim.Run) -> float:
    df = run.to_pandas()
    return float(sum((df[f"plant.{y}"] - df[f"ref.{y}"]).abs().sum() for y in ("h1", "h2")))


def test_the_tracking_law_applies_each_input_at_its_own_dead_time(
        models: dict[str, Path]) -> None:
    """On the plant whose qb acts six samples after qa, the controller that knows both dead
    times tracks the set-point steps with less IAE than one that takes none or six samples
    for both, without violations; its plans keep qb's first six inputs at those applied."""
    from cosim.adapters.robust_mpc import RobustMPCController

    plans: list[tuple[np.ndarray, np.ndarray]] = []
    original = RobustMPCController.step

    def step(self: RobustMPCController, t: float, dt: float) -> None:
        original(self, t, dt)
        if self.mpc.held.prefix.depth:
            plans.append((self.mpc.law.records[-1].result.u.copy(),
                          self.mpc.held._u_past.copy()))

    iae = {}
    RobustMPCController.step = step
    try:
        for name in ("mixed", "none", "both"):
            run = cosim.run(SCENARIO, plant=f"model:{models['mixed']}", model=models[name],
                            figure=False)
            assert run.status == "ok", run.reason
            assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())
            iae[name] = _iae(run)
            if name == "mixed":
                info = run.summary["controller_summary"]
                assert info["dead_time"] == 0 and info["dead_times"] == [0, 6]
    finally:
        RobustMPCController.step = original
    assert iae["mixed"] < 0.85 * min(iae["none"], iae["both"]), iae
    # qb's stage i < 6 is the input applied 6 - i samples before, stage 6 the one applied
    # now (u_past after the step: the last 6, this one the newest), to the solver's rounding
    assert len(plans) == 1601
    for u, past in plans:
        np.testing.assert_allclose(u[1:7, 1], past[:, 1], rtol=0.0, atol=1e-12)


def test_an_uncertified_run_applies_each_input_at_its_own_dead_time(
        models: dict[str, Path], tmp_path: Path) -> None:
    """A set-point next to the box's edge makes the run uncertified, the law replaced by the
    one on the measured tightening: that law's FHOCP fixes qb's first six inputs too, so on
    the model itself its one-step prediction is exact (before, it applied the first stage of
    both inputs, and predicted qb six samples early)."""
    sc = tmp_path / "edge.csv"
    sc.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n100,1.97,1.0\n600,,\n")
    run = cosim.run(sc, plant=f"model:{models['mixed']}", model=models["mixed"],
                    figure=False)
    assert run.status == "ok", run.reason
    info = run.summary["controller_summary"]
    assert info["certified"] is False and info["dead_times"] == [0, 6]
    first = [out["rms_by_step"][0] for out in
             info["operator"]["prediction_error"]["outputs"].values()]
    assert max(first) < 1e-9, first
    assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())


def test_the_paper_law_applies_each_input_at_its_own_dead_time(
        models: dict[str, Path]) -> None:
    """The paper's law with the horizon lengthened by qb's extra dead time: no violation,
    at most the fallbacks of the first two samples."""
    run = cosim.run(SCENARIO, plant=f"model:{models['mixed']}", model=models["mixed"],
                    options={"law": "paper", "N": 21}, figure=False)
    assert run.status == "ok", run.reason
    assert run.summary["controller_summary"]["fallbacks"] <= 2
    assert all(v["count"] == 0 for v in run.summary["kpis"]["violations"].values())


@pytest.mark.parametrize("options, edge", [({}, False), ({"law": "paper"}, False), ({}, True)],
                         ids=["tracking", "paper", "tracking-uncertified"])
def test_the_compiled_step_replays_the_python_controller_with_mixed_dead_times(
        models: dict[str, Path], options: dict, edge: bool) -> None:
    """The C step of a design whose inputs act 1 and 3 samples late, fed what the Python
    controller saw through set-point steps: its inputs, statuses and fallbacks to the bit;
    also made uncertified by a set-point next to the box's edge (``edge``: the law on the
    measured tightening, whose FHOCP must fix the slower input's first stages as the C step
    does)."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=models["short"], **options)
    ctrl.setup(0.0)
    refs = [(0.65, 0.65)] * 20 + [(1.97, 1.0) if edge else (1.0, 1.1)] * 30 + [(0.7, 0.9)] * 30
    if edge:
        ctrl.mpc.expect_setpoints([{"h1": 1.97, "h2": 1.0}])
        assert not ctrl.mpc.certification.certified
        ctrl.setup(0.0)   # the run starts on the law it was switched to
    design = ctrl.mpc.export_design()
    assert design.dead_time == 1 and design.delays.tolist() == [1, 3]
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    for _ in replayed(ctrl, compiled, refs):
        pass
    compiled.close()


def test_the_controller_fmu_applies_each_input_at_its_own_dead_time(
        models: dict[str, Path], tmp_path: Path) -> None:
    """``cosim export-fmu`` of the model whose inputs act 1 and 3 samples late, in closed loop
    with that plant: the Python controller's inputs, to the bit."""
    fmu = tmp_path / "Controller.fmu"
    assert main(["export-fmu", str(models["short"]), "--out", str(fmu), "--quiet"]) == 0
    plant = f"model:{models['short']}"
    py = cosim.run(SCENARIO, plant=plant, model=models["short"], figure=False).to_pandas()
    run = cosim.run(SCENARIO, plant=plant, controller=str(fmu), figure=False).to_pandas()
    for u in ("qa", "qb"):
        np.testing.assert_array_equal(run[f"ctrl.{u}"].to_numpy(), py[f"ctrl.{u}"].to_numpy())


def test_a_dead_time_beyond_the_free_stages_is_refused_in_words(
        models: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["run", str(SCENARIO), "--plant", f"model:{models['mixed']}", "--model",
                 str(models["mixed"]), "--option", "N=6", "--out", str(tmp_path / "o"),
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    assert "an input's dead time exceeds the shortest by 6 samples" in err, err
