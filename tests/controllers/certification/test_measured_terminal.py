"""The uncertified mode's measured terminal weight (controllers.certification.measured_terminal):
``eq:definition_s`` on the model's linearisation at its steady states, finite exactly when they
are stable, and what a certificate with ``ν ≥ 1`` makes of it."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov

from controllers.certification import certificates as certs
from controllers.certification import grade
from controllers.certification.bounds import terminal_weight
from controllers.certification.measured_terminal import (
    equivalent_contraction,
    measured_terminal_weight,
)
from controllers.equilibrium import jacobians
from controllers.model import DEFAULT_MODEL, GRUModel
from controllers.ocp.steady_state import steady_state
from tests.controllers.random_gru import random_gru_model


def test_the_weight_is_the_largest_cost_to_go_of_the_linearisations() -> None:
    model = random_gru_model(3, n=6)
    P, Q = model.params, np.diag([1.0, 2.0, 1.0, 1.0, 3.0, 1.0])
    found = measured_terminal_weight(P, Q, grid_points=3)
    assert math.isfinite(found.s) and found.radius < 1 and found.u is not None
    xs = steady_state(P, found.u, np.zeros(6))[0]
    A = jacobians(P, xs, found.u)[0]
    Pl = solve_discrete_lyapunov(A.T, Q)
    assert found.s == pytest.approx(6 * np.max(np.linalg.eigvalsh(Pl)), rel=1e-9)
    # every other grid point's cost to go is below the worst one's
    for a in (-1.0, 0.0, 1.0):
        for b in (-1.0, 0.0, 1.0):
            u = np.array([a, b])
            A = jacobians(P, steady_state(P, u, xs)[0], u)[0]
            assert 6 * np.max(np.linalg.eigvalsh(solve_discrete_lyapunov(A.T, Q))) \
                <= found.s * (1 + 1e-9)
    # eq:definition_s with the equivalent contraction gives the weight back
    rho = equivalent_contraction(6, Q, found.s)
    assert 0 <= rho < 1 and terminal_weight(6, Q, rho) == pytest.approx(found.s, rel=1e-12)


def test_an_unstable_linearisation_has_no_weight() -> None:
    model = random_gru_model(3, n=6)
    P = dict(model.params)
    P["b_z"] = np.full(6, -4.0)            # the update gate open: x+ ≈ h
    P["U_h"] = 3.0 * np.eye(6)            # h = tanh(3 x + ...): unstable near x = 0
    P["W_h"] = np.zeros_like(P["W_h"])
    P["b_h"] = np.zeros(6)
    found = measured_terminal_weight(P, np.eye(6), grid_points=3)
    assert found.s == math.inf and found.radius >= 1 and found.u is not None


@pytest.fixture(scope="module")
def recurrent_x10() -> GRUModel:
    """The shipped model with U_h scaled by 10: nu = 9.8, yet stable at its steady states."""
    model = copy.deepcopy(GRUModel.load(DEFAULT_MODEL))
    model.params["U_h"] = 10.0 * model.params["U_h"]
    return model


def test_a_model_the_theory_rejects_gets_the_measured_weight(recurrent_x10: GRUModel) -> None:
    cert = certs.compute_certificate(recurrent_x10, N=15)
    assert cert.nu > 1 and cert.s == math.inf
    assert math.isfinite(cert.s_measured) and cert.unusable() == ""
    assert cert.to_json()["s_measured"] == pytest.approx(cert.s_measured)
    margins = np.full(cert.a.shape, 0.05)
    cert_u = grade.uncertified_certificate(cert, margins)
    assert cert_u.s == cert.s_measured and cert_u.tightening == "measured"
    assert cert_u.rho_s < 1 and cert_u.alpha_min() == 0.0
    # a model the theory accepts measures none when certified; run uncertified, its design
    # takes the smaller of the theorem's weight and the measured one, with its contraction
    shipped = certs.compute_certificate(GRUModel.load(DEFAULT_MODEL), N=15)
    assert math.isfinite(shipped.s) and shipped.measured is None
    shipped_u = grade.uncertified_certificate(shipped, margins)
    assert shipped_u.s == min(shipped.s, shipped_u.measured.s) < shipped.s
    assert shipped_u.rho_s < shipped.rho_s


def test_without_a_stable_steady_state_the_model_is_not_usable(
        recurrent_x10: GRUModel) -> None:
    model = copy.deepcopy(recurrent_x10)
    n = model.params["U_h"].shape[0]
    model.params["b_z"] = np.full(n, -4.0)
    model.params["U_h"] = 3.0 * np.eye(n)
    model.params["W_h"] = np.zeros_like(model.params["W_h"])
    model.params["b_h"] = np.zeros(n)
    why = certs.compute_certificate(model, N=15).unusable()
    assert "spectral radius" in why and "steady state for qa = " in why and "m3/s" in why
    assert why.endswith(f"fix: {certs.NU_FIX}")
