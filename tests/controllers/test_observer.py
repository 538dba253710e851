"""GRU observer (controllers.observer) and the bounds of Lemma 3 (lem:Vo) on the model itself.

The plant is the δISS model with a bounded output perturbation (eq:perturbed-model):
x⁺ = f(x, u), y = U_o x + b_o + w_y, ‖w_y‖∞ ≤ w̄_y.
"""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from controllers.certification import certificates as certs
from controllers.certification import gain_design
from controllers.gru import output, step
from controllers.observer import GRUObserver
from tests.controllers.random_gru import random_gru_model


def _sig(v: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-v))


def observer_by_hand(p: dict, Lz: np.ndarray, Lr: np.ndarray, xh: np.ndarray, u: np.ndarray,
                     y: np.ndarray) -> np.ndarray:
    """eq:observer written out independently of controllers.gru."""
    e = y - (p["U_o"] @ xh + p["b_o"])
    z = _sig(p["W_z"] @ u + p["U_z"] @ xh + p["b_z"] + Lz @ e)
    r = _sig(p["W_r"] @ u + p["U_r"] @ xh + p["b_r"] + Lr @ e)
    h = np.tanh(p["W_h"] @ u + p["U_h"] @ (r * xh) + p["b_h"])
    return z * xh + (1 - z) * h


def test_observer_implements_eq_observer() -> None:
    m = random_gru_model(0, n=6)
    p = m.params
    rng = np.random.default_rng(0)
    Lz, Lr = rng.normal(0, 0.3, (6, 2)), rng.normal(0, 0.3, (6, 2))
    x0 = rng.uniform(-1, 1, 6)
    obs = GRUObserver(p, Lz, Lr, x0=x0)
    xh = x0.copy()
    for _ in range(30):
        u, y = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2)
        xh = observer_by_hand(p, Lz, Lr, xh, u, y)
        assert obs.make_step(u, y) == pytest.approx(xh, abs=1e-14)
    assert obs.k == 30


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None,
                    reason="no C compiler")
def test_observer_with_the_compiled_step_implements_eq_observer() -> None:
    """With a compiled kernel attached (what RobustMPCController does), the same update."""
    from controllers.kernel import compiled_kernel as ck

    m = random_gru_model(0, n=6)
    p = m.params
    k = ck.build(ck.KernelProblem(p, 3, np.eye(6), np.eye(2), np.zeros((1, 6)), 1.0))
    assert k is not None, ck.last_error
    rng = np.random.default_rng(0)
    Lz, Lr = rng.normal(0, 0.3, (6, 2)), rng.normal(0, 0.3, (6, 2))
    x0 = rng.uniform(-1, 1, 6)
    obs = GRUObserver(p, Lz, Lr, x0=x0)
    obs.kernel = k.workspace()
    xh = x0.copy()
    for _ in range(30):
        u, y = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2)
        xh = observer_by_hand(p, Lz, Lr, xh, u, y)
        assert obs.make_step(u, y) == pytest.approx(xh, abs=1e-14)


def test_zero_gains_is_the_open_loop_model() -> None:
    m = random_gru_model(1, n=5)
    p = m.params
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, 5)
    obs = GRUObserver(p, np.zeros((5, 2)), np.zeros((5, 2)), x0=x)
    for _ in range(10):
        u = rng.uniform(-1, 1, 2)
        x = step(p, x, u)
        assert obs.make_step(u, rng.uniform(-5, 5, 2)) == pytest.approx(x, abs=1e-15)


def _run_lemma3(seed: int, gain_factor: float, steps: int, w_y_bar: float) -> tuple[float,
                                                                                    float]:
    """Simulate plant + observer; assert eq:lyap-observer-neg-def and
    eq:lyap-observer-max-gain at every step; return the largest observed ratios."""
    m = random_gru_model(seed, n=10)
    p = m.params
    Lz, Lr = gain_design.observer_gains_lp(p)
    cert = certs.compute_certificate(m, N=15, L_z=gain_factor * Lz, L_r=gain_factor * Lr,
                                 w_y_bar=w_y_bar)
    assert cert.nu_o < 1  # lem:Vo needs it
    rng = np.random.default_rng(100 + seed)
    x = rng.uniform(-1, 1, 10)
    obs = GRUObserver.from_certificate(cert, x0=rng.uniform(-1, 1, 10))
    worst_contraction = worst_gain = 0.0
    for k in range(steps):
        u = rng.uniform(-1, 1, 2)
        w = rng.uniform(-w_y_bar, w_y_bar, 2) if k % 3 else np.zeros(2)
        y = output(p, x) + w
        e = np.max(np.abs(x - obs.x_hat))
        f_hat = step(p, obs.x_hat, u)
        x = step(p, x, u)
        xh = obs.make_step(u, y)
        e_next = np.max(np.abs(x - xh))
        wn = np.max(np.abs(w))
        assert np.max(np.abs(x)) <= 1 and np.max(np.abs(xh)) <= 1  # X positively invariant
        # eq:lyap-observer-neg-def
        assert e_next <= cert.rho_o * e + cert.kappa * wn + 1e-13
        gap = np.max(np.abs(xh - f_hat))
        # eq:lyap-observer-max-gain
        assert gap <= cert.L_max * e + cert.kappa * wn + 1e-13
        if e > 1e-6:
            worst_contraction = max(worst_contraction, (e_next - cert.kappa * wn) / e)
            worst_gain = max(worst_gain, (gap - cert.kappa * wn) / e)
        if k % 50 == 49:  # re-excite a large estimation error
            x = rng.uniform(-1, 1, 10)
    return worst_contraction / cert.rho_o, worst_gain / max(cert.L_max, 1e-300)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lemma3_bounds_hold_on_the_model(seed: int) -> None:
    c_ratio, g_ratio = _run_lemma3(seed, gain_factor=1.0, steps=1500, w_y_bar=0.1)
    # the bounds are not vacuous: the observed worst case uses a good part of them
    assert 0.5 < c_ratio <= 1.0
    assert 0.0 < g_ratio <= 1.0


def test_lemma3_bounds_hold_with_large_gains_and_noise() -> None:
    # gains 1.8× the LP gains (ν_o ≤ ν < 1, ν_o is convex in the scale) and large noise
    # make the κ terms dominate
    _run_lemma3(3, gain_factor=1.8, steps=1500, w_y_bar=0.5)


def test_e_o_bounds_the_estimation_error() -> None:
    """If ‖x_0 − x̂_0‖∞ ≤ ê_o,0, then ‖x_k − x̂_k‖∞ ≤ ê_o,k (eq:eo-evolution, eq:X-mpc)."""
    m = random_gru_model(4, n=10)
    p = m.params
    cert = certs.compute_certificate(m, N=15, w_y_bar=0.2, e_o0=0.3)
    rng = np.random.default_rng(4)
    x = rng.uniform(-0.6, 0.6, 10)
    obs = GRUObserver.from_certificate(cert, x0=x + rng.uniform(-0.3, 0.3, 10))
    expected = cert.e_o(800)
    for k in range(800):
        assert np.max(np.abs(x - obs.x_hat)) <= obs.e_o + 1e-13
        assert obs.e_o == pytest.approx(expected[k], rel=1e-12)
        u = rng.uniform(-1, 1, 2)
        y = output(p, x) + rng.choice([-0.2, 0.2], 2)  # worst-case magnitude
        obs.make_step(u, y)
        x = step(p, x, u)


def test_estimation_error_converges_without_perturbation() -> None:
    m = random_gru_model(5, n=10)
    p = m.params
    cert = certs.compute_certificate(m, N=15, w_y_bar=0.0)
    rng = np.random.default_rng(5)
    x = rng.uniform(-1, 1, 10)
    obs = GRUObserver.from_certificate(cert, x0=-x)
    for _ in range(2000):
        u = rng.uniform(-1, 1, 2)
        obs.make_step(u, output(p, x))
        x = step(p, x, u)
    assert np.max(np.abs(x - obs.x_hat)) < 2 * cert.rho_o**2000 + 1e-12


def test_initialisation_at_the_equilibrium_for_the_first_output() -> None:
    m = random_gru_model(6)
    p = m.params
    cert = certs.compute_certificate(m, N=15, w_y_bar=0.01)
    obs = GRUObserver.from_certificate(cert)
    assert obs.x_hat is None
    y0 = m.normalize_y(np.array([1.1, 0.9]))
    x0 = obs.init_from_output(y0)
    assert output(p, x0) == pytest.approx(y0, abs=1e-9)
    # first make_step without an explicit x0 does the same initialisation
    obs2 = GRUObserver.from_certificate(cert)
    u = np.array([0.1, -0.2])
    assert obs2.make_step(u, y0) == pytest.approx(step(p, x0, u), abs=1e-9)
    obs2.reset(e_o0=0.5)
    assert obs2.x_hat is None and obs2.e_o == 0.5 and obs2.k == 0
