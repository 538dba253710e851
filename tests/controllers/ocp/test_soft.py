"""Softened output constraints (controllers.ocp.soft): exact derivatives of the slacks'
terms, the compiled kernel's SOFT variant against the numpy twin, the hard problem's answer
wherever that one has one (an exact penalty), and an answer where it has none."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.certification import certificates as certs
from controllers.equilibrium import equilibrium
from controllers.errors import DesignError
from controllers.laws.paper.reference import FixedSetpoint
from controllers.laws.tracking.reference import ArtificialSteadyState
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.solve_status import SolveStatus
from tests.controllers.random_gru import random_gru_model


def _fh(cert: object, law: str, soft: bool, **options: object) -> FHOCP:
    ref = FixedSetpoint() if law == "paper" else ArtificialSteadyState(
        1e3, 0.05, ys_bounds=options.pop("ys_bounds", None))
    return FHOCP.from_certificate(cert, reference=ref, soft=soft, du_weight=0.1, **options)


@pytest.fixture(scope="module")
def small() -> object:
    """A small random model's certificate (N = 5)."""
    return certs.compute_certificate(random_gru_model(4, n=6), N=5, gain_scale=0.0,
                                     w_y_bar=0.01)


@pytest.mark.parametrize("law", ["paper", "tracking"])
def test_the_slacks_terms_have_exact_derivatives(small: object, law: str) -> None:
    """∇f, ∂g/∂w and the Hessian of the Lagrangian against central differences, at a point
    whose slacks are positive."""
    fh = _fh(small, law, True)
    nlp = fh.numpy_nlp()
    rng = np.random.default_rng(1)
    wv, pv = nlp._self_test_point(rng)
    wv[fh.slacks.idx] = rng.uniform(0.05, 0.3, fh.nsl)
    lg = rng.normal(0, 1, fh.ng)
    _, grad = nlp.gradient(wv, pv)
    _, J = nlp.jacobian(wv, pv)
    H = nlp.hessian(wv, pv, np.array([1.0]), lg)
    eps = 1e-6
    for i in fh.slacks.idx:
        e = np.zeros(fh.nw)
        e[i] = eps
        fd = (nlp.f(wv + e, pv)[0] - nlp.f(wv - e, pv)[0]) / (2 * eps)
        assert fd == pytest.approx(grad[i], rel=1e-6)
        Jfd = (nlp.g(wv + e, pv)[0] - nlp.g(wv - e, pv)[0]) / (2 * eps)
        assert np.max(np.abs(Jfd - J[:, i])) < 1e-6
        gl = [nlp.gradient(w, pv)[1] + nlp.jacobian(w, pv)[1].T @ lg
              for w in (wv + e, wv - e)]
        assert np.max(np.abs((gl[0] - gl[1]) / (2 * eps) - H[:, i])) < 1e-5 * np.max(np.abs(H))
    assert np.all(np.any(J[:, fh.slacks.idx] != 0, axis=0))   # each slack is in some row


@pytest.mark.parametrize("law", ["paper", "tracking"])
def test_the_compiled_soft_kernel_agrees_with_the_numpy_twin(small: object, law: str) -> None:
    fh = _fh(small, law, True).setup()
    assert fh.kernel is not None, fh.kernel_error
    assert fh.numpy_nlp().self_test(fh.kernel, fh.sqp_options["hessian_eigen_clip"]) < 1e-9


def test_the_penalty_is_exact_where_the_hard_problem_has_an_answer(model: object,
                                                                   cert: object) -> None:
    """The paper's FHOCP from states where the hard problem is feasible: the softened
    problem alone (no hard phase first) gives the same plan, nothing softened."""
    hard, soft = (_fh(cert, "paper", s, sqp_options={"max_iter": 200}).setup()
                  for s in (False, True))
    soft.always_soften = True
    for y0, y_bar in [((0.0, 0.0), (0.1, 0.1)), ((0.15, -0.1), (0.0, 0.05)),
                      ((-0.1, -0.1), (0.12, 0.12))]:
        x_hat, _ = equilibrium(model, np.array(y0))
        ref = cert.reference(np.array(y_bar), check=False)
        a, b = (fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
                for fh in (hard, soft))
        assert a.success and b.success, (a.status, b.status)
        assert b.softened <= 1e-7
        np.testing.assert_allclose(b.u, a.u, atol=1e-6)
        assert b.cost == pytest.approx(a.cost, rel=1e-6, abs=1e-9)


def test_a_problem_without_a_hard_answer_has_a_soft_one(model: object, cert: object) -> None:
    """ê_o so large that the i = 0 row and the rows after it fail at x̂: the hard FHOCP is
    infeasible (reported without solving); the softened one answers, its excess said."""
    hard, soft = (_fh(cert, "paper", s).setup() for s in (False, True))
    x_hat, _ = equilibrium(model, np.array([0.0, 0.0]))
    ref = cert.reference(np.array([0.1, 0.1]))
    a, b = (fh.solve(x_hat, 1.0, ref.x_bar, ref.u_bar, ref.alpha) for fh in (hard, soft))
    assert a.status == SolveStatus.INFEASIBLE_X0 and not a.success
    assert b.success, b.status
    assert b.softened > 0.1 and b.constraint_violation == 0.0


def test_the_tracking_law_answers_with_no_admissible_steady_state(cert: object) -> None:
    """``Y_s`` empty (its rows' right-hand sides below the box): the hard tracking FHOCP's
    QP has no feasible point, the softened one steers to the least excess."""
    model = cert.model
    ys = np.full(cert.q, -1.5)
    hard, soft = (_fh(cert, "tracking", s, ys_bounds=ys, sqp_options={"max_iter": 100}).setup()
                  for s in (False, True))
    x_hat, _ = equilibrium(model, np.array([0.0, 0.0]))
    r = np.array([0.1, 0.1])
    u0 = np.zeros((cert.N, model.m))
    a, b = (fh.solve(x_hat, 0.02, r, u0, np.zeros(model.m), x_hat) for fh in (hard, soft))
    assert not a.success
    assert b.success, b.status
    assert b.softened > 0.4 and b.iterations < 40


def test_the_multiple_shooting_baseline_stays_hard(cert: object) -> None:
    with pytest.raises(DesignError, match="single-shooting"):
        FHOCP.from_certificate(cert, reference=FixedSetpoint(), soft=True,
                               formulation="multiple-shooting")
