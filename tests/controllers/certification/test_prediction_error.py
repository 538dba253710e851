"""The paper's ``w̄_y`` measured on data (:func:`controllers.certification.prediction_error.
w_y_bar_from_data`)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.certification.prediction_error import w_y_bar_from_data
from controllers.errors import DataError
from tests.controllers.random_gru import random_gru_model


def test_w_y_bar_from_data_recovers_the_output_perturbation(tmp_path) -> None:
    """Data made by the model itself plus a known bounded w_y: w̄_y is its maximum."""
    from controllers.gru import simulate

    m = random_gru_model(2)
    rng = np.random.default_rng(0)
    T = 1500
    u = np.repeat(rng.uniform(-1, 1, (T // 10, 2)), 10, axis=0)
    _, xi = simulate(m.params, rng.uniform(-0.5, 0.5, 20), u)
    w = rng.uniform(-0.03, 0.03, xi.shape)
    split = np.array(["train"] * 500 + ["val"] * 500 + ["test"] * 500)
    w[split == "test"] *= 0.5
    w[1234, 1] = 0.04  # the test maximum (normalised); train/val have larger noise
    y = m.denormalize_y(xi + w)
    up = m.denormalize_u(u)
    assert w_y_bar_from_data(m, up, y, split) == pytest.approx(0.04, abs=1e-5)
    # an inconsistent record (no test rows) is a one-line error naming the split
    with pytest.raises(DataError, match="no rows in split 'test'"):
        w_y_bar_from_data(m, up[:1000], y[:1000], split[:1000])
