"""A random δISS GRU model in the paper's convention, for tests that need a model (seeded)."""

from __future__ import annotations

import numpy as np

from controllers.model import GRUModel
from controllers.problem import FOURTANK


def random_gru_model(seed: int = 0, n: int = 20, m: int = 2, p: int = 2) -> GRUModel:
    """A small-weight GRU with ``b_z ≈ 2`` (slow, δISS: ν < 1) and four-tank normalisation.

    Inputs are normalised so that the physical box maps to ``‖u‖∞ ≤ 1``; outputs use
    ``y = (h − 1) / 1`` so that the output box [0, 2] m maps to ``[−1, 1]``.
    """
    rng = np.random.default_rng(seed)

    def mat(rows: int, cols: int, row_sum: float) -> np.ndarray:
        a = rng.uniform(-1.0, 1.0, (rows, cols))
        return a * (row_sum / np.abs(a).sum(axis=1, keepdims=True))

    params = {
        "W_z": mat(n, m, 0.1), "U_z": mat(n, n, 0.05), "b_z": rng.uniform(1.9, 2.1, n),
        "W_r": mat(n, m, 0.3), "U_r": mat(n, n, 0.3), "b_r": rng.uniform(-0.2, 0.2, n),
        "W_h": mat(n, m, 1.2), "U_h": mat(n, n, 0.6), "b_h": rng.uniform(-0.1, 0.1, n),
        "U_o": mat(p, n, 1.5), "b_o": np.zeros(p),
    }
    lo = np.array([b[0] for b in FOURTANK.input_bounds])
    hi = np.array([b[1] for b in FOURTANK.input_bounds])
    return GRUModel(params=params, u_offset=(lo + hi) / 2, u_scale=(hi - lo) / 2,
                    y_offset=np.ones(p), y_scale=np.ones(p),
                    input_names=list(FOURTANK.inputs)[:m], input_units=["m3/s"] * m,
                    output_names=list(FOURTANK.outputs)[:p], output_units=["m"] * p,
                    Ts=FOURTANK.Ts, training={"source": f"random_gru_model(seed={seed})"})
