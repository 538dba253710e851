"""The seven first example plants give the same outputs, to the bit, as before the shared base
became declarative (``fmus/examples/plant_base.py``: the outputs as states, their start values
as the settling's start, the dead times of transfer-function channels).

Each plant's built FMU runs 120 samples of a fixed input table (every input stepping through
levels inside its problem's box every 10 samples: the golden-ratio sequence, no random
generator) with its tunable parameters away from their defaults; the SHA-256 of its outputs
(float64, in the problem's order, sample after sample) is the one the FMUs built from commit
4598f75 gave, recorded before the change.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import fmpy
import numpy as np
import pytest

from controllers.problem_file import load
from tests import example_builds

#: Tunable parameters set away from their defaults.
PARAMETERS = {"cstr": {"k0_factor": 1.05, "UA_factor": 0.93, "CAf": 1.02, "Tf": 338.0},
              "heater": {"T_amb": 17.0, "C_factor": 1.07},
              "heater_dead_time": {"T_amb": 23.0, "C_factor": 0.95},
              "mixing_tank": {"T_hot": 68.0, "Cv_factor": 1.04},
              "furnace": {"T_amb": 25.0, "K_factor": 1.1, "C_factor": 0.9},
              "furnace_load": {"T_amb": 18.0, "K_factor": 0.9, "C_factor": 1.1},
              "furnace3": {"T_amb": 22.0, "K_factor": 1.05}}
#: SHA-256 of each plant's outputs, from the FMUs of commit 4598f75.
RECORDED = {
    "cstr": "b1f166b782bffda15858ba3399b5627212b246f555f321a29bbbff3aa2835951",
    "heater": "f902c14ba4cd0c9ee3d309f921515553a220da1a37d33af131ba0df6f1f85fd7",
    "heater_dead_time": "7f279bb0eccb896287776c85eaead862308bd834d729262b0a9879b6b4159df3",
    "mixing_tank": "9d0a27b166ab90efb9b217857c76d1a6306a8781c375b11a44583b90998ffe16",
    "furnace": "3d058451944bba09aedbe8185f053a81faa1c8fd04c6445cb7e18f81742b7ea1",
    "furnace_load": "a604cf4d8b953e15c21c3805498d219101dd8aee56fce43762d9a7e5759615f4",
    "furnace3": "f8f3be2b05660913a0b4c74ef7cebb39e1a8f21d22468d02468b7d0523c9f6fa",
}
SAMPLES, HOLD = 120, 10


def trajectory(fmu: Path, plant: str) -> np.ndarray:
    """The plant's outputs under the fixed input table (rows: samples)."""
    problem = load(example_builds.problem_file(plant))
    boxes = {c.variable: (c.min, c.max) for c in (*problem.inputs, *problem.disturbances)}
    inputs = [v.name for v in fmpy.read_model_description(str(fmu)).modelVariables
              if v.causality == "input"]
    table = np.zeros(SAMPLES, dtype=[("time", float)] + [(name, float) for name in inputs])
    table["time"] = np.arange(SAMPLES) * problem.Ts
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    for j, name in enumerate(inputs):
        lo, hi = boxes[name]
        share = ((np.arange(SAMPLES) // HOLD + 1) * golden + j / len(inputs)) % 1.0
        table[name] = lo + share * (hi - lo)
    r = fmpy.simulate_fmu(str(fmu), stop_time=(SAMPLES - 1) * problem.Ts,
                          output_interval=problem.Ts, input=table,
                          start_values=PARAMETERS[plant],
                          output=[c.variable for c in problem.outputs])
    return np.column_stack([r[c.variable] for c in problem.outputs])


def digest(values: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(values, dtype="<f8").tobytes()).hexdigest()


@pytest.mark.parametrize("plant", sorted(RECORDED))
def test_the_first_example_plants_give_the_same_outputs_to_the_bit(plant: str,
                                                                   tmp_path: Path) -> None:
    values = trajectory(example_builds.build(plant, tmp_path), plant)
    assert values.shape[0] == SAMPLES and np.all(np.isfinite(values))
    assert digest(values) == RECORDED[plant], (plant, values[-1].tolist())
