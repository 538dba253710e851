"""FMU state save/restore and serialisation (canGetAndSetFMUstate, canSerializeFMUstate)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fmus.fourtank_reference import random_inputs
from tests.fmus.fourtank_run import LEVELS, Plant


def _run(plant: Plant, u: np.ndarray) -> np.ndarray:
    out = []
    for qa, qb in u:
        plant.set(qa=qa, qb=qb)
        plant.do_step(25.0)
        out.append(plant.get(*LEVELS))
    return np.array(out)


@pytest.mark.parametrize("which", ["fmu2_path", "fmu3_path"])
def test_restore_and_deserialise_replay_identically(which, request):
    plant = Plant(request.getfixturevalue(which), "cs")
    v2 = plant.version == 2
    fmu = plant.fmu
    u = random_inputs(60, seed=21)
    try:
        plant.initialize()
        _run(plant, u[:20])
        saved = fmu.getFMUstate() if v2 else fmu.getFMUState()
        blob = fmu.serializeFMUstate(saved) if v2 else fmu.serializeFMUState(saved)
        t_saved = plant.time
        first = _run(plant, u[20:])

        (fmu.setFMUstate if v2 else fmu.setFMUState)(saved)
        plant.time = t_saved
        np.testing.assert_array_equal(_run(plant, u[20:]), first)

        restored = fmu.deSerializeFMUstate(blob) if v2 else fmu.deserializeFMUState(blob)
        (fmu.setFMUstate if v2 else fmu.setFMUState)(restored)
        plant.time = t_saved
        np.testing.assert_array_equal(_run(plant, u[20:]), first)
        (fmu.freeFMUstate if v2 else fmu.freeFMUState)(saved)
        (fmu.freeFMUstate if v2 else fmu.freeFMUState)(restored)
    finally:
        plant.close()
