"""The hand-written derivatives of :mod:`controllers.ocp.shooting` against casadi AD of gru.step."""

import casadi as ca
import numpy as np
import pytest

from controllers import gru
from controllers.ocp.shooting import GRUShooting
from tests.controllers.random_gru import random_gru_model


@pytest.fixture(scope="module")
def setup():
    P = random_gru_model(3, n=6, m=2, p=2).params
    n, m, _ = gru.dimensions(P)
    Pc = {k: ca.DM(v) for k, v in P.items()}
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    mu = ca.SX.sym("mu", n)
    xp = gru.step(Pc, x, u, gru.casadi_ops())
    v = ca.vertcat(x, u)
    F = ca.Function("F", [x, u, mu], [xp, ca.jacobian(xp, x), ca.jacobian(xp, u),
                                      ca.hessian(ca.dot(mu, xp), v)[0]])
    return P, n, m, F


def _shooting(setup, N: int, seed: int, spread: float):
    """The shooting of ``N`` steps of the test GRU, a state drawn in ``[-spread, spread]``,
    inputs in ``[-1, 1]`` and the generator that drew them."""
    P, n, m, _ = setup
    rng = np.random.default_rng(seed)
    return GRUShooting(P, N), rng.uniform(-spread, spread, n), rng.uniform(-1, 1, (N, m)), rng


def test_stage_derivatives_match_casadi(setup):
    _, n, _, F = setup
    N = 4
    sh, x0, u, rng = _shooting(setup, N, seed=0, spread=0.8)
    mu = rng.normal(size=(N, n))
    ro = sh.rollout(x0, u)
    W = sh.stage_hessians(ro, mu)
    for i in range(N):
        xp, A, B, H = (np.asarray(v) for v in F(ro.x[i], u[i], mu[i]))
        np.testing.assert_allclose(ro.x[i + 1], xp.ravel(), atol=1e-14)
        np.testing.assert_allclose(ro.A[i], A, atol=1e-13)
        np.testing.assert_allclose(ro.B[i], B, atol=1e-13)
        np.testing.assert_allclose(W[i], H, atol=1e-12)


def test_sensitivities_match_finite_differences(setup):
    m, N = setup[2], 5
    sh, x0, u, _ = _shooting(setup, N, seed=1, spread=0.5)
    S = sh.rollout(x0, u).S
    eps = 1e-6
    for j in range(N * m):
        du = np.zeros(N * m)
        du[j] = eps
        xp = sh.rollout(x0, u + du.reshape(N, m), derivatives=False).x
        xm = sh.rollout(x0, u - du.reshape(N, m), derivatives=False).x
        np.testing.assert_allclose((xp - xm) / (2 * eps), S[:, :, j], atol=1e-8)
