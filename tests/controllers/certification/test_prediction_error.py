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


def test_offset_filter_is_the_kalman_gain_of_the_measured_noise_and_drift() -> None:
    """A residual that is a random walk (σ_w = 0.01 a sample) seen through white noise
    (σ_v = 0.02), in two experiments: ``ρ`` and ``q`` measured to a few percent and ``β`` the
    local-level model's steady-state Kalman gain; the same drift without noise: ``β = 1``; the
    noise alone: :data:`BETA_MIN`; one ``β``, the smallest of the outputs'."""
    from controllers.certification.prediction_error import BETA_MIN, offset_filter

    rng = np.random.default_rng(3)
    T = 40000
    walk = np.cumsum(rng.normal(0, 0.01, (T, 2)), axis=0)
    noise = rng.normal(0, 0.02, (T, 2))
    spans = [(0, T // 4), (T // 4 + 10, T // 2), (T // 2, T)]   # never bridged
    measured = offset_filter(walk + noise, np.zeros((T, 2)), spans)
    assert measured is not None
    np.testing.assert_allclose(measured.noise, 0.02, rtol=0.05)
    np.testing.assert_allclose(measured.drift, 0.01, rtol=0.1)
    lam = (0.02 / 0.01) ** 2
    assert measured.beta == pytest.approx(2 / (1 + np.sqrt(1 + 4 * lam)), rel=0.1)
    smooth = np.cumsum(np.cumsum(rng.normal(0, 1e-4, (T, 2)), axis=0), axis=0)
    assert offset_filter(smooth, np.zeros((T, 2)), spans).beta == 1.0
    assert offset_filter(noise, np.zeros((T, 2)), spans).beta == BETA_MIN
    mixed = np.column_stack([smooth[:, 0], (walk + noise)[:, 1]])
    assert offset_filter(mixed, np.zeros((T, 2)), spans).beta == pytest.approx(
        measured.beta, rel=0.1)
    assert offset_filter(walk[:2], np.zeros((2, 2)), [(0, 2)]) is None
