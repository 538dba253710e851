"""The admissible reference governor (controllers.governor): equilibria by continuation, and
every step it takes comes with a sequence that is feasible for the new set-point."""

import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.fhocp import FHOCP
from controllers.governor import ReferenceGovernor, equilibrium_newton
from controllers.gru import output, simulate
from tests.controllers.random_gru import N


@pytest.fixture(scope="module")
def fhocp(cert):
    return FHOCP.from_certificate(cert).setup()


def test_equilibrium_by_continuation_matches_least_squares(model):
    x0, u0 = equilibrium(model, np.array([0.0, 0.0]))
    y = np.array([0.08, -0.05])
    eq = equilibrium_newton(model.params, y, x0, u0)
    assert eq is not None
    x, u = eq
    x_ref, u_ref = equilibrium(model, y)
    np.testing.assert_allclose(u, u_ref, atol=1e-9)
    np.testing.assert_allclose(x, x_ref, atol=1e-9)
    np.testing.assert_allclose(output(model.params, x), y, atol=1e-10)
    # an output the inputs cannot hold inside ‖u‖∞ ≤ 1: no answer
    assert equilibrium_newton(model.params, np.array([5.0, 5.0]), x0, u0) is None


def test_governor_step_is_feasible_and_bounded(model, cert, fhocp):
    """From a converged plan at v = (−0.1, −0.1), a move towards r = (0.1, 0.1): λ ≤ λ_max, and
    the returned sequence satisfies every FHOCP constraint for the new set-point (checked
    here with an independent numpy rollout)."""
    v = np.array([-0.1, -0.1])
    ref = cert.reference(v)
    fhocp.reset_warm_start()
    sol = fhocp.solve(ref.x_bar, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert sol.success
    gov = ReferenceGovernor(cert, fhocp)
    r = np.array([0.1, 0.1])
    assert gov.step(ref.x_bar, 0.02, v, ref.x_bar, ref.u_bar, r, None).lam == 0.0
    for lam_max in (1.0, 0.25):
        gs = gov.step(sol.x[1], 0.02, v, ref.x_bar, ref.u_bar, r, sol.u, lam_max)
        assert 0.0 < gs.lam <= lam_max
        np.testing.assert_allclose(gs.y, v + gs.lam * (r - v), atol=1e-15)
        assert cert.ok(gs.y)
        assert gs.alpha == pytest.approx(cert.alpha(gs.y))
        x, yi = simulate(model.params, sol.x[1], gs.candidate)
        ub = cert.h - cert.a[:N] * 0.02 - cert.b[:N] - cert.w_L
        assert np.all(yi[1:] @ cert.L.T <= ub[1:] + 1e-12)
        assert np.max(np.abs(x[N] - gs.x_bar)) <= gs.alpha
        assert np.max(np.abs(gs.candidate)) <= 1.0
        # the FHOCP at the governed set-point, started from the candidate, solves
        res = fhocp.solve(sol.x[1], 0.02, gs.x_bar, gs.u_bar, gs.alpha, u_init=gs.candidate)
        assert res.feasible
