"""Model equilibria (controllers.equilibrium): residuals, box, closed form, unreachable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.equilibrium import (
    UnreachableSetpoint,
    equilibrium,
    equilibrium_for_output,
    jacobians,
    state_equilibrium,
)
from controllers.errors import ControllersError
from controllers.gru import output, step
from tests.controllers.random_gru import random_gru_model


def test_jacobians_match_finite_differences() -> None:
    rng = np.random.default_rng(0)
    p = random_gru_model(0, n=7).params
    for _ in range(5):
        x, u = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 2)
        fx, fu = jacobians(p, x, u)
        eps = 1e-6
        fd_x = np.array([(step(p, x + eps * e, u) - step(p, x - eps * e, u)) / (2 * eps)
                         for e in np.eye(7)]).T
        fd_u = np.array([(step(p, x, u + eps * e) - step(p, x, u - eps * e)) / (2 * eps)
                         for e in np.eye(2)]).T
        assert fx == pytest.approx(fd_x, abs=1e-8)
        assert fu == pytest.approx(fd_u, abs=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_equilibrium_residuals_are_tiny(seed: int) -> None:
    m = random_gru_model(seed)
    p = m.params
    # set-points generated from inputs inside the box are reachable by construction
    for u_true in np.random.default_rng(seed).uniform(-0.9, 0.9, (4, 2)):
        y_bar = output(p, state_equilibrium(p, u_true))
        x, u = equilibrium(m, y_bar)
        assert np.max(np.abs(step(p, x, u) - x)) < 1e-12
        assert np.max(np.abs(output(p, x) - y_bar)) < 1e-9
        assert np.max(np.abs(u)) <= 1.0 and np.max(np.abs(x)) < 1.0
        assert u == pytest.approx(u_true, abs=1e-6)  # the map u → ȳ is injective here


def test_closed_form_scalar_model() -> None:
    """n = m = p = 1 with U_z = U_r = U_h = 0: x̄ = tanh(W_h ū + b_h), ȳ = U_o x̄ + b_o."""
    p = {"W_z": np.array([[0.3]]), "U_z": np.zeros((1, 1)), "b_z": np.array([2.0]),
         "W_r": np.array([[0.1]]), "U_r": np.zeros((1, 1)), "b_r": np.array([0.0]),
         "W_h": np.array([[0.8]]), "U_h": np.zeros((1, 1)), "b_h": np.array([0.1]),
         "U_o": np.array([[1.5]]), "b_o": np.array([0.2])}
    y_bar = 0.9
    x_hand = (0.9 - 0.2) / 1.5                       # 0.4667
    u_hand = (math.atanh(x_hand) - 0.1) / 0.8        # 0.5827
    x, u = equilibrium(p, [y_bar])
    assert x[0] == pytest.approx(x_hand, abs=1e-12)
    assert u[0] == pytest.approx(u_hand, abs=1e-10)
    # ȳ = 1.5 needs tanh(0.8 u + 0.1) = 0.8667, u = 1.54 > 1: not reachable
    with pytest.raises(UnreachableSetpoint, match="closest reachable"):
        equilibrium(p, [1.5])
    x_best, u_best = equilibrium_for_output(p, [1.5])
    assert u_best[0] == pytest.approx(1.0)  # saturated input gives the closest output
    assert output(p, x_best)[0] == pytest.approx(0.2 + 1.5 * math.tanh(0.9), abs=1e-10)


def test_unreachable_setpoint_message_in_physical_units() -> None:
    m = random_gru_model(0)
    y_far = m.normalize_y(np.array([5.0, 1.0]))
    with pytest.raises(ControllersError) as info:
        equilibrium(m, y_far)
    msg = str(info.value)
    assert "h1=5 m, h2=1 m" in msg and "not reachable" in msg and "\n" not in msg
    # the closest reachable output named in the message is what equilibrium_for_output gives
    x, _ = equilibrium_for_output(m, y_far)
    reach = m.denormalize_y(output(m.params, x))
    assert f"h1={reach[0]:.4g} m" in msg


def test_deterministic() -> None:
    m = random_gru_model(3)
    y = output(m.params, state_equilibrium(m.params, np.array([0.2, -0.4])))
    a = equilibrium(m, y)
    b = equilibrium(m, y)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
