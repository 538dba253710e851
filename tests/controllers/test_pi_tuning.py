"""PI loops tuned from the GRU model: RGA, pairing, FOPDT fit, SIMC (controllers.pi_tuning)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers import pi_tuning
from controllers.equilibrium import state_equilibrium
from controllers.errors import DesignError, UnreachableSetpoint
from controllers.model import DEFAULT_MODEL, GRUModel
from tests.controllers.random_gru import random_gru_model


def test_relative_gain_array_is_bristols() -> None:
    g = np.array([[2.0, 1.0], [1.0, 3.0]])
    lam = g[0, 0] * g[1, 1] / (g[0, 0] * g[1, 1] - g[0, 1] * g[1, 0])  # 2x2 closed form
    rga = pi_tuning.relative_gain_array(g)
    assert np.allclose(rga, [[lam, 1 - lam], [1 - lam, lam]], rtol=1e-14)
    g3 = np.array([[1.0, 0.2, -0.5], [0.3, 2.0, 0.1], [0.4, -0.6, 1.5]])
    rga3 = pi_tuning.relative_gain_array(g3)
    assert np.allclose(rga3.sum(axis=0), 1) and np.allclose(rga3.sum(axis=1), 1)
    # independent of units: scaling rows and columns leaves it unchanged
    assert np.allclose(pi_tuning.relative_gain_array(np.diag([1e3, 2.0, 5e-4]) @ g3
                                                     @ np.diag([7.0, 1e-3, 3.0])), rga3)
    with pytest.raises(DesignError, match="is singular"):
        pi_tuning.relative_gain_array(np.array([[1.0, 2.0], [2.0, 4.0]]))
    with pytest.raises(DesignError, match="square gain matrix"):
        pi_tuning.relative_gain_array(np.ones((2, 3)))


def test_best_pairing_takes_positive_gains_closest_to_one() -> None:
    # the four-tank's: the diagonal pairing has relative gain -0.4
    assert pi_tuning.best_pairing(np.array([[-0.4, 1.4], [1.4, -0.4]])) == (1, 0)
    assert pi_tuning.best_pairing(np.array([[0.9, 0.1], [0.1, 0.9]])) == (0, 1)
    # 0 < λ < 1: both pairings positive, the one nearer one wins
    assert pi_tuning.best_pairing(np.array([[0.3, 0.7], [0.7, 0.3]])) == (1, 0)
    # 3x3: the pairing (0, 2, 1) has Σ|λ − 1| = 0.5, (1, 0, 2) 1.8, the others a λ < 0
    rga = np.array([[1.1, 0.4, -0.5], [0.2, -0.1, 0.9], [-0.3, 0.7, 0.6]])
    assert pi_tuning.best_pairing(rga) == (0, 2, 1)
    with pytest.raises(DesignError) as info:
        pi_tuning.best_pairing(np.array([[2.0, -0.5, -0.5], [2.0, -0.5, -0.5],
                                         [-3.0, 2.0, 2.0]]), ["a", "b", "c"], ["x", "y", "z"])
    assert str(info.value) == (
        "no pairing of the outputs (a, b, c) with the inputs (x, y, z) has positive relative "
        "gains: RGA [2 -0.5 -0.5; 2 -0.5 -0.5; -3 2 2] (rows outputs, columns inputs); a "
        "decentralised PI cannot be tuned (give the loops)")


def test_fopdt_fit_recovers_a_sampled_fopdt() -> None:
    Ts, tau, theta = 5.0, 400.0, 60.0
    t = Ts * np.arange(600)
    s = np.where(t > theta, 1.0 - np.exp(-(t - theta) / tau), 0.0)
    tau_fit, theta_fit = pi_tuning.fit_fopdt(s, Ts)
    assert abs(tau_fit - tau) < 0.01 * tau and abs(theta_fit - theta) < 0.02 * theta
    # no delay: θ is one sample (u_k acts on y_k+1)
    s0 = 1.0 - np.exp(-t / tau)
    assert pi_tuning.fit_fopdt(s0, Ts)[1] == Ts
    with pytest.raises(DesignError, match="reaches 50% of its final change within 3"):
        pi_tuning.fit_fopdt(np.array([0.0, 0.2, 0.4, 0.5]), Ts)


def test_simc_rules() -> None:
    K, Ti, tau_c = pi_tuning.simc(2.0, 10.0, 1.0)  # τc = θ: K = τ / (2 k θ), Ti = min(τ, 8θ)
    assert (K, Ti, tau_c) == (2.5, 8.0, 1.0)
    K, Ti, _ = pi_tuning.simc(-2.0, 10.0, 1.0, tau_c=4.0)  # sign of k; Ti = τ when smaller
    assert (K, Ti) == (-1.0, 10.0)
    with pytest.raises(DesignError, match="non-zero finite process gain"):
        pi_tuning.simc(0.0, 10.0, 1.0)
    with pytest.raises(DesignError, match="tau_c must be a positive number"):
        pi_tuning.simc(1.0, 10.0, 1.0, tau_c=-1.0)


def test_the_shipped_model_gives_the_cross_pairing() -> None:
    """The four-tank problem file's comment: the diagonal pairing's relative gain is
    γa γb / (γa + γb − 1) = −0.4, the cross pairing's 1.4; the identified model agrees."""
    model = GRUModel.load(DEFAULT_MODEL)
    tuning = pi_tuning.tune(model)
    assert np.allclose(tuning.y_op, [1.0, 1.0], atol=1e-7)  # the output box's middle
    assert [(lt.output, lt.input) for lt in tuning.loops] == [("h1", "qb"), ("h2", "qa")]
    assert abs(tuning.rga[0, 1] - 1.4) < 0.05 and abs(tuning.rga[0, 0] + 0.4) < 0.05
    for lt in tuning.loops:
        assert lt.k > 0 and lt.K > 0 and lt.relative_gain == tuning.rga[
            tuning.output_names.index(lt.output), tuning.input_names.index(lt.input)]
        # SIMC with τc = θ; θ above one sample (the cross channels pass through two tanks)
        assert model.Ts < lt.theta == lt.tau_c and lt.Tt == lt.Ti
        assert math.isclose(lt.K, lt.tau / (lt.k * 2 * lt.theta), rel_tol=1e-12)
        assert lt.Ti == min(lt.tau, 8 * lt.theta)
    # the gains agree with a finite difference of the model's equilibria
    _, u, _ = pi_tuning.operating_point(model)

    du = np.array([0.0, 1e-5])
    y_plus = model.params["U_o"] @ state_equilibrium(model.params, u + du) + model.params["b_o"]
    y_minus = model.params["U_o"] @ state_equilibrium(model.params, u - du) + model.params["b_o"]
    fd = (y_plus - y_minus) / 2e-5 * model.y_scale / model.u_scale[1]
    assert np.allclose(tuning.gain[:, 1], fd, rtol=1e-5)
    # deterministic
    again = pi_tuning.tune(model)
    assert again.loops == tuning.loops and np.array_equal(again.rga, tuning.rga)


def test_a_given_setpoint_moves_the_operating_point() -> None:
    model = GRUModel.load(DEFAULT_MODEL)
    tuning = pi_tuning.tune(model, setpoint=[0.7, 1.2], tau_c=300.0)
    assert np.allclose(tuning.y_op, [0.7, 1.2], atol=1e-7)
    assert all(lt.tau_c == 300.0 for lt in tuning.loops)
    with pytest.raises(UnreachableSetpoint, match=r"h1=1\.9 m, h2=0\.1 m is not reachable"):
        pi_tuning.tune(model, setpoint=[1.9, 0.1])


def test_no_pairing_with_positive_relative_gains_is_refused() -> None:
    model = random_gru_model(14, n=4, m=3, p=3)
    with pytest.raises(DesignError) as info:
        pi_tuning.tune(model)
    msg = str(info.value)
    assert msg.startswith("no pairing of the outputs (h1, h2, y3) with the inputs (qa, qb, u3) "
                          "has positive relative gains: RGA [-2.8 6.97 -3.17; 4.49 -12.7")
    with pytest.raises(DesignError, match="as many inputs as outputs; the model has 2 inputs "
                                          "and 3 outputs"):
        pi_tuning.tune(random_gru_model(0, m=2, p=3))
