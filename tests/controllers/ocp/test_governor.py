"""The admissible reference governor (controllers.laws.paper.governor): equilibria by continuation,
and every step it takes comes with a sequence that is feasible for the new set-point."""

import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.gru import output, simulate
from controllers.laws.paper.governor import ReferenceGovernor, equilibrium_newton
from controllers.laws.paper.reference import FixedSetpoint
from controllers.ocp.fhocp import FHOCP
from tests.controllers.random_gru import N


@pytest.fixture(scope="module")
def fhocp(cert):
    return FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()


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


@pytest.mark.parametrize(("m", "p"), [(1, 2), (3, 2)])
def test_governor_for_non_square_problems(m: int, p: int) -> None:
    """More outputs than inputs (1 × 2): a governed set-point is the equilibrium output of
    ū(v) + λ (ū(r) − ū(v)), on the model's curve of them, not the (unreachable) point
    v + λ (r − v) of the segment; more inputs than outputs (3 × 2): the point of the segment,
    by the least-squares Newton continuation. Each step's sequence is feasible, and the
    nominal closed loop reaches r exactly."""
    from controllers.certification import gain_design
    from controllers.equilibrium import equilibrium_output
    from controllers.gru import step
    from tests.controllers.random_gru import random_gru_model

    model = random_gru_model(7, n=8, m=m, p=p)
    x0, v = equilibrium_output(model.params, np.full(m, -0.3))
    _, r = equilibrium_output(model.params, np.full(m, 0.3), x0)
    theta, cert = gain_design.choose_gain_scale(model, [v, r], N=10, w_y_bar=0.002)
    assert theta is not None
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    gov = ReferenceGovernor(cert, fh)
    ref = cert.reference(v)
    x_bar, u_bar, alpha, x = ref.x_bar, ref.u_bar, ref.alpha, ref.x_bar
    sol = fh.solve(x, 0.0, x_bar, u_bar, alpha, warm=False)
    assert sol.success
    gs = gov.step(x, 0.0, v, x_bar, u_bar, r, sol.u, 0.25)
    assert 0 < gs.lam <= 0.25
    on_segment = v + gs.lam * (r - v)
    if p > m:   # ū(r) = 0.3: the map u → ȳ is injective
        u_lam = u_bar + gs.lam * (np.full(m, 0.3) - u_bar)
        np.testing.assert_allclose(gs.u_bar, u_lam, atol=1e-9)
        np.testing.assert_allclose(gs.y, equilibrium_output(model.params, u_lam, x_bar)[1],
                                   atol=1e-9)
        assert np.max(np.abs(gs.y - on_segment)) > 1e-6
    else:
        np.testing.assert_allclose(gs.y, on_segment, atol=1e-15)
    plan, last, lams = sol.u, True, []
    for _ in range(60):
        gs = gov.govern(x, 0.0, v, x_bar, u_bar, r, plan, last)
        if gs.lam > 0:
            lams.append(gs.lam)
            v, x_bar, u_bar, alpha = gs.y, gs.x_bar, gs.u_bar, gs.alpha
            assert cert.ok(v) and np.max(np.abs(gs.candidate)) <= 1.0
            assert np.max(np.abs(output(model.params, x_bar) - v)) < 1e-10
            assert np.max(np.abs(step(model.params, x_bar, u_bar) - x_bar)) < 1e-10
            assert gov.feasible(x, 0.0, gs.candidate, x_bar, alpha)
        res = fh.solve(x, 0.0, x_bar, u_bar, alpha, u_init=gs.candidate)
        last = res.success
        plan = res.u if res.success else (gs.candidate if gs.candidate is not None else plan)
        x = step(model.params, x, plan[0])
        if np.array_equal(v, r):
            break
    assert lams and np.array_equal(v, r)
