"""The compiled FHOCP kernel (controllers.compiled_kernel): the numpy derivatives' numbers, the
same solves, the same equilibria; and the fallback to numpy without a compiler."""

from __future__ import annotations

import copy
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from controllers import compiled_kernel as ck
from controllers.equilibrium import equilibrium, equilibrium_newton
from controllers.fhocp import FHOCP
from controllers.nlp_single_shooting import SingleShootingNLP
from tests.controllers.random_gru import H_BOX, L_BOX, random_gru_model

needs_cc = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None,
                              reason="no C compiler")


def rel(a: object, b: object) -> float:
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float).reshape(b.shape)
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def random_fhocp(n: int, N: int, seed: int, **kw: object) -> FHOCP:
    """A random δISS GRU with a box problem (certificate-like data, hypotheses unchecked)."""
    model = random_gru_model(seed, n=n)
    q = L_BOX.shape[0]
    a = np.linspace(0.0, 0.5, N + 1)[:, None] * np.ones((1, q))
    b = np.linspace(0.0, 0.02, N + 1)[:, None] * np.ones((1, q))
    return FHOCP(model.params, N, np.eye(n), 0.01 * np.eye(2), L_BOX, 4 * H_BOX,
                 np.full(q, 0.002), a, b, float(50 * n), **kw).setup()


@needs_cc
@pytest.mark.parametrize(("n", "N", "mode"), [(20, 15, "w"), (20, 15, "contract"),
                                              (9, 7, "w"), (12, 30, "w")])
def test_kernel_matches_the_numpy_derivatives(n: int, N: int, mode: str,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRU_MPC_KERNEL_MODE", mode)
    fh = random_fhocp(n, N, seed=n + N, kernel="numpy")
    k = ck.build(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2)
    assert k is not None, ck.last_error
    nlp = SingleShootingNLP(fh, None)
    nlp.eigen_clip = 1e-2
    rng = np.random.default_rng(0)
    for _ in range(5):
        w = np.concatenate([rng.uniform(-1, 1, N * fh.m), [0.05]])
        p = np.concatenate([rng.uniform(-0.7, 0.7, 2 * n), rng.uniform(-0.9, 0.9, fh.m)])
        lg = rng.normal(0, 1, fh.ng) * rng.choice([1e-3, 1.0, 100.0], fh.ng)
        for a, b in zip(k.external("jac_fg")(w, p), nlp.jac_fg(w, p), strict=True):
            assert rel(a, b) < 1e-12
        f, g = k.external("fg")(w, p)
        assert rel(f, nlp.f(w, p)[0]) < 1e-12 and rel(g, nlp.g(w, p)[0]) < 1e-12
        assert rel(k.external("hess_l")(w, p, 1.0, lg),
                   nlp.hessian_convex(w, p, np.array([1.0]), lg)[0]) < 1e-12
        u = w[:-1].reshape(N, fh.m)
        assert rel(k.simulate(p[:n], u), nlp.shoot.rollout(p[:n], u).x) < 1e-13


@needs_cc
def test_same_solves_as_the_numpy_fhocp(cert) -> None:
    """Same status and iterations, the optimum to 1e-9, from identical warm starts."""
    a = FHOCP.from_certificate(cert, kernel="numpy").setup()
    b = FHOCP.from_certificate(cert).setup()
    assert a.kernel is None and b.kernel is not None
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    for y in ([0.1, 0.1], [0.0, 0.05], [0.1, 0.1]):
        ref = cert.reference(np.array(y))
        for _ in range(3):
            warm = copy.deepcopy(a._warm)
            ra = a.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
            b._warm = warm
            rb = b.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
            assert (ra.status, ra.iterations) == (rb.status, rb.iterations)
            if ra.success:
                assert np.max(np.abs(ra.u - rb.u)) < 1e-9
                assert abs(ra.cost - rb.cost) < 1e-9 * (1 + abs(ra.cost))
            x_hat = a.rollout(x_hat, ra.u)[1]


@needs_cc
def test_compiled_equilibrium_newton_matches_numpy(cert) -> None:
    fh = FHOCP.from_certificate(cert).setup()
    ref = cert.reference(np.array([0.0, 0.0]))
    for y in ([0.1, 0.1], [0.05, -0.05], [3.0, 3.0]):
        a = equilibrium_newton(cert.params, np.array(y), ref.x_bar, ref.u_bar)
        b = fh.kernel.eq_newton(np.array(y), ref.x_bar, ref.u_bar)
        assert (a is None) == (b is None)
        if a is not None:
            assert np.max(np.abs(a[0] - b[0])) < 1e-12 and np.max(np.abs(a[1] - b[1])) < 1e-12


def test_without_a_compiler_the_numpy_derivatives_give_the_same_answer(
        cert, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fh = FHOCP.from_certificate(cert).setup()
    assert fh.kernel is None and "no C compiler 'no-such-compiler-xyz'" in fh.kernel_error
    assert [str(w.message) for w in caught if "kernel" in str(w.message)] == [
        "compiled FHOCP kernel unavailable (no C compiler 'no-such-compiler-xyz' on PATH); "
        "using the numpy derivatives"]
    ref = cert.reference(np.array([0.1, 0.1]))
    r1 = fh.solve(ref.x_bar, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
    r2 = FHOCP.from_certificate(cert, kernel="numpy").setup().solve(
        ref.x_bar, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
    assert r1.status == r2.status and np.array_equal(r1.u, r2.u)


def test_disabled_by_the_environment(cert, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRU_MPC_KERNEL", "0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fh = FHOCP.from_certificate(cert).setup()
    assert fh.kernel is None and "disabled by GRU_MPC_KERNEL=0" in fh.kernel_error


@needs_cc
def test_cache_reuses_a_build_and_keys_on_the_problem(cert, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    fh = FHOCP.from_certificate(cert, kernel="numpy").setup()
    k1 = ck.build(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2)
    k2 = ck.build(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2)
    assert k1 is not None and k1.path == k2.path and len(list(tmp_path.glob("*.so"))) == 1
    k3 = ck.build(fh.params, fh.N, 2 * fh.Q, fh.R, fh.DUo, fh.s, 1e-2)  # other weights
    assert k3.path != k1.path and len(list(tmp_path.glob("*.so"))) == 2


def test_ipopt_and_multiple_shooting_keep_numpy(cert) -> None:
    assert FHOCP.from_certificate(cert, solver="ipopt").setup().kernel is None
    assert FHOCP.from_certificate(cert, formulation="multiple-shooting").setup().kernel is None
