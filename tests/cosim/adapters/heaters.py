"""The example heaters with their ambient temperature measured, for the tests of measured
disturbances (:mod:`test_disturbances`: the heater; :mod:`test_dead_time`: the heater whose power
acts two samples late): their briefly trained models, a cache of their closed-loop runs (one run
feeding every test that asserts on it) and what the tests compare."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cosim.cli import main

#: the paper's law with a horizon for the heater's time constants (its default N = 15 is the
#: four tanks'), the offset-free set-point
PAPER = {"law": "paper", "N": 60, "offset_free": True}


def trained(folder: Path, fmu: Path, problem: Path, steps: int, epochs: int
            ) -> dict[str, Path]:
    """``generate-data`` of ``steps`` samples on ``fmu`` under ``problem``, then a GRU of 6
    states trained ``epochs`` epochs on them: ``data`` and ``model`` in ``folder``."""
    data, model = folder / "data.csv", folder / "gru.json"
    assert main(["generate-data", "--plant", str(fmu), "--problem", str(problem), "--steps",
                 str(steps), "--out", str(data), "--quiet"]) == 0
    assert main(["train", str(data), "--epochs", str(epochs), "--n", "6", "--out", str(model),
                 "--quiet"]) == 0
    return {"data": data, "model": model}


def run_cache(case: dict[str, Path]) -> Callable[..., Any]:
    """``run(model="model", **options)``: the robust MPC of ``case[model]`` on the case's
    scenario and plant (``cosim.run``), run once per model and options and kept."""
    import cosim

    done: dict[tuple[str, str], Any] = {}

    def run(model: str = "model", **options: Any) -> Any:
        key = (model, json.dumps(options, sort_keys=True))
        if key not in done:
            done[key] = cosim.run(case["scenario"], plant=case["fmu"], model=case[model],
                                  options=options, figure=False)
        return done[key]
    return run


def iae(table: Any, start: float, end: float) -> float:
    """The IAE of the temperature [degC s] over ``start <= time < end`` of a run's table
    (20 s samples)."""
    inside = table[(table["time"] >= start) & (table["time"] < end)]
    return float((inside["ref.T"] - inside["plant.T"]).abs().sum() * 20.0)


def previewed(model: Path, folder: Path) -> Path:
    """``model`` with its disturbance declared known ahead (``preview = true``)."""
    doc = json.loads(model.read_text())
    for entry in doc["problem"]["disturbances"]:
        entry["preview"] = True
    path = folder / "gru_preview.json"
    path.write_text(json.dumps(doc))
    return path


def replay(ctrl: Any, compiled: Any, steps: int, ref: Callable[[int], float],
           dist: Callable[[int], float]) -> None:
    """Step the Python controller ``ctrl`` and the exported C step ``compiled`` on the same
    measurements (a first-order response to the set-point ``ref(k)`` with sensor noise, the
    ambient ``dist(k)``): the same inputs, statuses, fallbacks and targets, to the bit."""
    ctrl.setup(0.0)
    rng = np.random.default_rng(3)
    y = 45.0
    for k in range(steps):
        r, d = ref(k), dist(k)
        y = y + 0.3 * (r - y) * 0.2 + rng.normal(0.0, 0.05)
        ctrl.set_inputs({"T": y, "ref.T": r, "dist.T_in": d})
        ctrl.step(20.0 * k, 20.0)
        out = compiled.step(np.array([y]), np.array([r]), np.array([d]))
        np.testing.assert_array_equal(out["u"], [ctrl.get_outputs()["P"]])
        diag = ctrl.diagnostics()
        assert (out["status"], out["fallback"]) == (diag["status"], diag["fallback"]), k
        np.testing.assert_array_equal(out["y_target"], [diag["y_model_T"]])
    compiled.close()


def replay_paper_law(model: Path, dead_time: int) -> None:
    """The paper's law's C step (governor, offset-free set-point) of ``model`` fed what the
    Python controller saw, ambient steps included, one of which leaves the set-point
    unreachable (the last reference kept, said in the user's names): its inputs, statuses
    and fallbacks to the bit, step by step (:func:`replay`); the design's dead time is
    ``dead_time``."""
    from controllers.kernel.controller_source import CompiledController, build, design_data
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(model=model, **PAPER)
    ctrl.expect_setpoints([{"T": 45.0}, {"T": 55.0}, {"T": 60.0}])   # uncertified for them
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    assert design.q == 1 and design.dead_time == dead_time
    compiled = CompiledController(*build(design), design_data(design), n_inputs=1,
                                  n_outputs=1, n_disturbances=1)
    replay(ctrl, compiled, 160, lambda k: 45.0 if k < 20 else 55.0 if k < 70 else 60.0,
           lambda k: 20.0 if k < 40 else 10.0 if k < 90 else 30.0 if k < 120 else 5.0)
    info = ctrl.mpc.law.summary()
    assert info["disturbance_refusals"] >= 1
    assert any("is not reachable at T_in=5 degC: the closest reachable output" in r
               for r in info["setpoint_rejections"]), info["setpoint_rejections"]
