"""What the tests of the exported controller (:mod:`test_controller_export`,
:mod:`test_controller_export_plants`, :mod:`test_compiled_step`) compare: the FMU's or the
compiled step's inputs against the Python controller's, and the example plants they run on."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

import cosim

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_steps.csv"
#: The issue's bar: the FMU's inputs within this share of each input's box of the Python
#: controller's (they are equal to the bit on this machine).
TOL = 1e-9
#: The paper's law without its governor (the paper's controller), and with it (its default).
PAPER_LAW = {"law": "paper", "governor": False}
GOVERNED = {"law": "paper", "governor": True}
#: The four tanks' input boxes [m3/s].
FOUR_TANKS = {"qa": (0.0, 9.05e-4), "qb": (0.0, 1.11e-3)}


def same_inputs(fmu_run: cosim.RunOutput, py_run: cosim.RunOutput, inputs: dict) -> None:
    """Both runs end alike (ok, or degraded where the Python controller fell back at more
    than a tenth of its steps: the FMU's fallback output counts them too) and as long, the
    FMU's ``inputs`` (name -> box) within :data:`TOL` of their boxes of the Python
    controller's, the same statuses, fallbacks and targets."""
    a, b = fmu_run.to_pandas(), py_run.to_pandas()
    assert fmu_run.status == py_run.status in ("ok", "degraded"), (fmu_run.reason,
                                                                   py_run.reason)
    assert len(a) == len(b)
    for name, (lo, hi) in inputs.items():
        worst = float(np.max(np.abs(a[f"ctrl.{name}"] - b[f"ctrl.{name}"]))) / (hi - lo)
        assert worst <= TOL, (name, worst)
    np.testing.assert_array_equal(a["ctrl.status"], b["ctrl.status"])
    np.testing.assert_array_equal(a["ctrl.fallback"], b["ctrl.fallback"])
    for name in (c.removeprefix("ctrl.y_model_") for c in b.columns
                 if c.startswith("ctrl.y_model_")):   # the steady output steered to
        np.testing.assert_array_equal(a[f"ctrl.target.{name}"], b[f"ctrl.y_model_{name}"])


def example_case(tmp_path: Path, plant_name: str, seed: int, steps: str
                 ) -> tuple[Path, Path, Path]:
    """An example plant of ``fmus/examples`` (pythonfmu), a GRU model of its problem, and the
    set-point scenario ``steps``."""
    from controllers.problem_file import load
    from tests import example_builds as examples
    from tests.controllers.random_gru import random_gru_model

    plant = examples.build(plant_name, tmp_path / "plants")
    model = random_gru_model(seed, n=10, problem=load(examples.problem_file(plant_name)))
    model.w_y_bar = 0.01
    path = tmp_path / f"{plant_name}_gru.json"
    model.save(path)
    scenario = tmp_path / "steps.csv"
    scenario.write_text(steps)
    return plant, path, scenario


def replayed(ctrl: object, compiled: object, refs: list[tuple[float, float]],
             y0: tuple[float, float] = (0.62, 0.71)) -> Iterator[dict]:
    """Step a Python controller ``ctrl`` of the four-tank's outputs and its compiled step on
    the same noisy measurements (a random walk from ``y0``) with the set-points ``refs`` (one
    per step): the same inputs (to the bit), statuses and fallbacks at every step; yields the
    compiled step's outputs."""
    rng = np.random.default_rng(5)
    y = np.array(y0, dtype=float)
    inputs = ctrl.problem.input_names
    for k, ref in enumerate(np.array(refs, dtype=float)):
        y = y + rng.normal(0.0, 2e-3, 2)
        ctrl.set_inputs({"h1": y[0], "h2": y[1], "ref.h1": ref[0], "ref.h2": ref[1]})
        ctrl.step(25.0 * k, 25.0)
        out = compiled.step(y, ref)
        u = np.array([ctrl.get_outputs()[n] for n in inputs])
        np.testing.assert_array_equal(out["u"], u)
        diag = ctrl.diagnostics()
        assert out["status"] == diag["status"]
        assert out["fallback"] == diag["fallback"]
        np.testing.assert_array_equal(out["y_target"], [diag["y_model_h1"], diag["y_model_h2"]])
        yield out
