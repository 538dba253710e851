"""Identification records (experiments, stretches), sensor limits found in data, the initial
state estimated from an experiment's first samples, and the ARX baseline."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.identification.initial_state import estimate_initial_state, free_run
from controllers.identification.linear import ARXModel, fit_arx, simulate
from controllers.identification.record import Record
from controllers.identification.saturation import detect, flags
from controllers.identification.training import init_params


def test_experiments_and_stretches() -> None:
    split = np.array(["train"] * 5 + ["val"] * 2 + ["train"] * 3 + ["test"] * 2)
    exp = np.array([0] * 7 + [1] * 5)
    r = Record(np.zeros((12, 1)), np.zeros((12, 1)), split, exp)
    assert r.experiments() == [(0, 7), (7, 12)]
    assert r.stretches("train") == [(0, 5), (7, 10)]
    assert r.stretches("val") == [(5, 7)] and r.has("test") and r.m == r.p == 1


def test_a_plateau_at_the_largest_value_is_a_sensor_limit() -> None:
    rng = np.random.default_rng(0)
    y = rng.uniform(-0.5, 0.5, (400, 2))
    y[100:130, 0] = 0.8                       # 30 samples at the top: a limit
    y[200, 1] = 0.9                           # one high sample: not a limit
    lim = detect(y)
    assert lim.upper == (0.8, None) and lim.lower == (None, None) and lim.any
    f = flags(y, lim)
    assert f[100:130, 0].tolist() == [1] * 30 and np.count_nonzero(f) == 30
    assert lim.clip(np.array([[1.0, 1.0]])).tolist() == [[0.8, 1.0]]
    assert lim.to_dict(["level", "temp"], np.array([5.0, 1.0]), np.array([5.0, 0.0])) == {
        "level": {"upper": 9.0}}


def test_the_initial_state_is_recovered_from_the_first_samples() -> None:
    """A model's own free run from a state far from its steady state: the estimate from 50
    samples reproduces the run much better than the steady state does."""
    rng = np.random.default_rng(2)
    P = init_params(4, 1, 2, 3)
    u = rng.uniform(-1, 1, (120, 1))
    x_true = rng.uniform(-0.8, 0.8, 4)
    y = free_run(P, u, x_true)
    x_hat = estimate_initial_state(P, u, y, samples=50)
    err_hat = np.max(np.abs(free_run(P, u, x_hat) - y))
    err_zero = np.max(np.abs(free_run(P, u, np.zeros(4)) - y))
    assert err_hat < 1e-2 * err_zero and np.all(np.abs(x_hat) <= 1.0)


def test_arx_recovers_an_arx_plant_and_picks_its_orders() -> None:
    rng = np.random.default_rng(1)
    T = 1500
    u = rng.uniform(-1, 1, (T, 1))
    y = np.zeros((T, 1))
    for t in range(2, T):
        y[t] = 1.2 * y[t - 1] - 0.4 * y[t - 2] + 0.3 * u[t - 1] + 0.1
    split = np.repeat(["train", "val", "test"], [1000, 250, 250])
    rec = Record(u, y, split, np.zeros(T, dtype=int))
    model = fit_arx(rec)
    assert isinstance(model, ARXModel) and model.na == 2 and model.nk == 1
    assert np.max(np.abs(simulate(model, rec) - y)) < 1e-8


def test_arx_simulation_that_diverges_is_infinite() -> None:
    model = ARXModel(1, 1, 0, np.array([[0.0], [2.0], [0.0]]))     # y_t = 2 y_{t-1}
    out = model.simulate(np.zeros((2000, 1)), np.ones((2000, 1)))
    assert np.isinf(out[-1, 0])


@pytest.mark.parametrize("bad", ["lengths"])
def test_a_record_with_disagreeing_arrays_is_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="disagree in length"):
        Record(np.zeros((5, 1)), np.zeros((4, 1)), np.array(["train"] * 5), np.zeros(5))
