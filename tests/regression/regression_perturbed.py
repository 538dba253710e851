"""Deliberately perturbed controllers: the regression suite must notice each of them.

Used as ``cosim run --controller tests.regression.regression_perturbed:<Class>`` (from the
repository root).
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from controllers.model import DEFAULT_MODEL
from cosim.adapters.pi import PIController
from cosim.adapters.robust_mpc import RobustMPCController


class PIGainUp(PIController):
    """The PI baseline with every loop gain ×1.1."""

    def __init__(self) -> None:
        base = PIController()
        super().__init__(loops=[replace(loop, K=1.1 * loop.K) for loop in base.loops])


class MPCInputWeight(RobustMPCController):
    """The robust MPC with R = 0.011·I instead of the paper's 0.01·I (R × 1.1)."""

    def __init__(self, **options: object) -> None:
        super().__init__(R=0.011 * np.eye(2), **options)


class MPCModelWeight(RobustMPCController):
    """The robust MPC on the shipped GRU with one weight (``U_o[0][0]``) changed by 1e-3."""

    def __init__(self, **options: object) -> None:
        doc = json.loads(DEFAULT_MODEL.read_text(encoding="utf-8"))
        doc["U_o"][0][0] += 1e-3
        path = Path(tempfile.mkdtemp(prefix="perturbed_model_")) / "model.json"
        path.write_text(json.dumps(doc), encoding="utf-8")
        super().__init__(model=path, **options)
