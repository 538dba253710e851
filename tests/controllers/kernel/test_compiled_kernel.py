"""The compiled FHOCP kernel (controllers.kernel.compiled_kernel): the numpy derivatives' numbers,
the
same solves, the same equilibria; and the fallback to numpy without a compiler."""

from __future__ import annotations

import copy
import os
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

from controllers.equilibrium import equilibrium, equilibrium_newton
from controllers.kernel import compiled_kernel as ck
from controllers.laws.paper.reference import FixedSetpoint
from controllers.ocp.fhocp import FHOCP, FHOCPData
from controllers.ocp.nlp_single_shooting import SingleShootingNLP, clip_eigenvalues
from tests.controllers.random_gru import random_gru_model

needs_cc = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None,
                              reason="no C compiler")


def rel(a: object, b: object) -> float:
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float).reshape(b.shape)
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def random_fhocp(n: int, N: int, seed: int, m: int = 2, p: int = 2, **kw: object) -> FHOCP:
    """A random δISS GRU of ``m`` inputs and ``p`` outputs with the box problem ``|y_j| ≤ 1``
    (certificate-like data, hypotheses unchecked; for m = p = 2 the shared test problem's
    rows ``L_BOX``, ``4 H_BOX``)."""
    model = random_gru_model(seed, n=n, m=m, p=p)
    L = np.vstack([np.eye(p), -np.eye(p)])
    q = L.shape[0]
    a = np.linspace(0.0, 0.5, N + 1)[:, None] * np.ones((1, q))
    b = np.linspace(0.0, 0.02, N + 1)[:, None] * np.ones((1, q))
    kw.setdefault("reference", FixedSetpoint())
    return FHOCP(FHOCPData(model.params, N, np.eye(n), 0.01 * np.eye(m), L, np.full(q, 1.0),
                           np.full(q, 0.002), a, b, float(50 * n)), **kw).setup()


@needs_cc
@pytest.mark.parametrize(("n", "N", "mode", "m", "p"), [
    (20, 15, "w", 2, 2), (20, 15, "contract", 2, 2), (20, 15, "backward", 2, 2),
    (9, 7, "w", 2, 2), (12, 30, "w", 2, 2), (12, 30, "backward", 2, 2),
    (33, 6, "w+blas", 2, 2), (33, 6, "contract+blas", 2, 2), (33, 6, "backward+blas", 2, 2),
    # other numbers of inputs and outputs: SISO, more inputs than outputs (N m = 45 >= 40:
    # LAPACK's eigenvalues when casadi ships OpenBLAS), more outputs than inputs
    (9, 7, "w", 1, 1), (11, 15, "w", 3, 2), (10, 12, "backward", 1, 3),
    (14, 6, "contract", 3, 1)])
def test_kernel_matches_the_numpy_derivatives(n: int, N: int, mode: str, m: int, p: int,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Every variant (``+blas``: the products through casadi's OpenBLAS, off by default), for
    any numbers of inputs ``m`` and outputs ``p``."""
    mode, _, blas = mode.partition("+")
    monkeypatch.setenv("GRU_MPC_KERNEL_MODE", mode)
    if blas:
        if ck.casadi_openblas() is None:
            pytest.skip("casadi ships no OpenBLAS here")
        monkeypatch.setenv("GRU_MPC_KERNEL_BLAS", "on")
    fh = random_fhocp(n, N, seed=n + N, m=m, p=p, kernel="numpy")
    assert (fh.m, fh.p, fh.q) == (m, p, 2 * p)
    k = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2))
    assert k is not None, ck.last_error
    assert ("-DGK_BLAS" in k.flags) == bool(blas)
    assert ({"w": None, "contract": "-DGK_CONTRACT", "backward": "-DGK_BACKWARD"}[mode]
            in (*k.flags, None))
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
        assert rel(k.workspace().simulate(p[:n], u), nlp.shoot.rollout(p[:n], u).x) < 1e-13


def test_the_variant_follows_the_flop_model(monkeypatch: pytest.MonkeyPatch) -> None:
    """W-mode for the paper's problem, contracted for large n, backward for long N."""
    monkeypatch.delenv("GRU_MPC_KERNEL_MODE", raising=False)
    assert ck.choose_mode(20, 2, 15) == "w"
    assert ck.choose_mode(80, 2, 15) == "contract"
    assert ck.choose_mode(20, 2, 60) == "backward"


def same_start_solves(a: FHOCP, b: FHOCP, cert, setpoints: list, repeats: int):
    """``(a's result, b's result)`` of the same FHOCPs along ``a``'s closed loop through
    ``setpoints`` (``repeats`` steps each), ``b`` warm-started exactly as ``a``."""
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    for y in setpoints:
        ref = cert.reference(np.array(y))
        for _ in range(repeats):
            warm = copy.deepcopy(a.warm_start)
            ra = a.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
            b.warm_start = warm
            yield ra, b.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
            x_hat = a.rollout(x_hat, ra.u)[1]


@needs_cc
def test_same_solves_as_the_numpy_fhocp(cert) -> None:
    """Same status and iterations, the optimum to 1e-9, from identical warm starts (the
    kernel's derivatives in casadi's SQP loop, as the numpy callbacks; its own loop:
    tests/controllers/kernel/test_kernel_sqp.py)."""
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint(), kernel="numpy").setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                               sqp_options={"loop": "casadi"}).setup()
    assert a.kernel is None and b.kernel is not None
    for ra, rb in same_start_solves(a, b, cert, [[0.1, 0.1], [0.0, 0.05], [0.1, 0.1]], 3):
        assert (ra.status, ra.iterations) == (rb.status, rb.iterations)
        if ra.success:
            assert np.max(np.abs(ra.u - rb.u)) < 1e-9
            assert abs(ra.cost - rb.cost) < 1e-9 * (1 + abs(ra.cost))


@needs_cc
def test_compiled_equilibrium_newton_matches_numpy(cert) -> None:
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    ref = cert.reference(np.array([0.0, 0.0]))
    for y in ([0.1, 0.1], [0.05, -0.05], [3.0, 3.0]):
        a = equilibrium_newton(cert.params, np.array(y), ref.x_bar, ref.u_bar)
        b = fh.kernel.eq_newton(np.array(y), ref.x_bar, ref.u_bar)
        assert (a is None) == (b is None)
        if a is not None:
            assert np.max(np.abs(a[0] - b[0])) < 1e-12 and np.max(np.abs(a[1] - b[1])) < 1e-12


@needs_cc
@pytest.mark.parametrize(("m", "p"), [(1, 1), (3, 3), (3, 2), (1, 2)])
def test_compiled_equilibrium_newton_for_every_shape(m: int, p: int) -> None:
    """eq_newton (the governor's continuation) is numpy's iteration to 1e-12 when m = p, and
    its least-squares steps by the normal equations otherwise (numpy's by an SVD: the
    minimum-norm step when m > p, Gauss-Newton when p > m), to the same equilibrium within
    1e-9. Each reaches an equilibrium; off the surface of equilibrium outputs (p > m) there
    is none."""
    from types import SimpleNamespace

    from controllers.equilibrium import equilibrium_output
    from controllers.gru import output, step
    from controllers.laws.paper.governor import ReferenceGovernor

    fh = random_fhocp(9, 6, seed=10 * m + p, m=m, p=p)
    assert fh.kernel is not None, fh.kernel_error
    assert "eq_newton" in fh.kernel.kernel.c
    gov = ReferenceGovernor(SimpleNamespace(params=fh.params), fh)
    x0, y0 = equilibrium_output(fh.params, np.zeros(m))
    u0 = np.zeros(m)
    rng = np.random.default_rng(m + p)
    for _ in range(3):
        _, y = equilibrium_output(fh.params, rng.uniform(-0.3, 0.3, m), x0)
        a = equilibrium_newton(fh.params, y, x0, u0)
        b = gov.newton(y, x0, u0)
        assert a is not None and b is not None
        if m == p:
            assert np.max(np.abs(a[0] - b[0])) < 1e-12 and np.max(np.abs(a[1] - b[1])) < 1e-12
        else:
            assert np.max(np.abs(a[0] - b[0])) < 1e-9 and np.max(np.abs(a[1] - b[1])) < 1e-9
        x, u = b
        assert np.max(np.abs(step(fh.params, x, u) - x)) < 1e-10
        assert np.max(np.abs(output(fh.params, x) - y)) < 1e-10 and np.max(np.abs(u)) <= 1
    if p > m:   # off the surface of equilibrium outputs: no equilibrium, numpy and governor
        off = y0 + 0.05 * np.linalg.svd(np.vstack([np.ones(p), np.eye(p)[:m]]))[2][-1]
        assert gov.newton(off, x0, u0) is None


def test_without_a_compiler_the_numpy_derivatives_give_the_same_answer(
        cert, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fh = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    assert fh.kernel is None and "no C compiler 'no-such-compiler-xyz'" in fh.kernel_error
    assert [str(w.message) for w in caught if "kernel" in str(w.message)] == [
        "compiled FHOCP kernel unavailable (no C compiler 'no-such-compiler-xyz' on PATH); "
        "using the numpy derivatives"]
    ref = cert.reference(np.array([0.1, 0.1]))
    r1 = fh.solve(ref.x_bar, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
    r2 = FHOCP.from_certificate(cert, reference=FixedSetpoint(), kernel="numpy").setup().solve(
        ref.x_bar, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
    assert r1.status == r2.status and np.array_equal(r1.u, r2.u)


def test_disabled_by_the_environment(cert, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRU_MPC_KERNEL", "0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fh = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    assert fh.kernel is None and "disabled by GRU_MPC_KERNEL=0" in fh.kernel_error


@needs_cc
def test_cache_reuses_a_build_and_keys_on_the_problem(cert, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(), kernel="numpy").setup()
    k1 = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2))
    k2 = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2))
    assert k1 is not None and k1.path == k2.path and len(list(tmp_path.glob("*.c"))) == 1
    other = ck.KernelProblem(fh.params, fh.N, 2 * fh.Q, fh.R, fh.DUo, fh.s, 1e-2)  # weights
    k3 = ck.build(other)
    # other numbers, same dimensions: their own copy of the library, not compiled again
    assert k3 is not None and k3.path != k1.path and len(list(tmp_path.glob("*.c"))) == 1
    w, p = np.full(k1.nw, 0.2), np.full(k1.npar, 0.1)
    x0, u = p[:fh.n], np.full((fh.N, fh.m), 0.2)
    assert np.array_equal(k1.workspace().simulate(x0, u), k3.workspace().simulate(x0, u))
    lam_x, lam_g = np.zeros(k1.nw), np.zeros(k1.ng)
    assert not np.allclose(k1.workspace().grad_l(w, p, lam_x, lam_g),
                           k3.workspace().grad_l(w, p, lam_x, lam_g))   # Q, twice Q


def test_ipopt_and_multiple_shooting_keep_numpy(cert) -> None:
    assert FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                  solver="ipopt").setup().kernel is None
    assert FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                  formulation="multiple-shooting").setup().kernel is None


@needs_cc
@pytest.mark.parametrize(("n", "N", "m", "p"), [(20, 15, 2, 2), (9, 7, 2, 2), (9, 7, 1, 1),
                                                (11, 8, 3, 2), (8, 9, 1, 3)])
def test_answer_check_and_observer_step_match_numpy(n: int, N: int, m: int, p: int) -> None:
    """assess / assess_w (cost, residuals, defect of an answer) and gru_step (eq:observer's
    update) against the law's cost, its residuals and controllers.gru.step, including answers
    outside the input box, violated output rows and terminal sets."""
    from controllers import gru
    from controllers.ocp.fhocp import FHOCPResult

    fh = random_fhocp(n, N, seed=3 * n + N, m=m, p=p, kernel="numpy")
    lib = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2, LUo=fh.LUo))
    assert lib is not None and lib.nl == fh.q, ck.last_error
    k = lib.workspace()
    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(40):
        x0 = rng.uniform(-0.7, 0.7, n)
        x_bar, u_bar = rng.uniform(-0.7, 0.7, n), rng.uniform(-0.9, 0.9, fh.m)
        w = np.concatenate([rng.uniform(-1.3, 1.3, N * fh.m), [0.05]])
        e_o, alpha = rng.uniform(0.0, 0.05), rng.uniform(0.0, 1.5)
        bounds = fh.tightened_bounds(e_o) * rng.choice([0.05, 1.0])  # some rows violated
        u = np.clip(w[:-1].reshape(N, fh.m), -1.0, 1.0)
        x = gru.simulate(fh.params, x0, u)[0]
        ref = FHOCPResult(u=u, x=x, cost=0.0, status="", success=False)
        fh.reference.residuals(ref, x, bounds, x_bar, alpha)
        uc, xk, out, _ = k.assess_w(w, np.concatenate([x0, x_bar, u_bar]), bounds, alpha)
        # the defect: the solver's trajectory (unclipped inputs) against the check's
        xs = gru.simulate(fh.params, x0, w[:-1].reshape(N, fh.m))[0]
        assert np.array_equal(uc, u) and rel(xk, x) < 1e-13
        assert abs(out.defect - np.max(np.abs(xs - x))) < 1e-13
        assert rel(out.cost, fh.reference.cost(x, u, x_bar, u_bar)) < 1e-12
        viol = max(0.0, out.violation_first, out.violation_rows, out.u_max - 1.0)
        assert abs(viol - ref.constraint_violation) < 1e-12
        assert abs(max(0.0, out.terminal_distance - alpha) - ref.terminal_violation) < 1e-12
        assert out.active == ref.active and out.steady_residual == 0.0
        seen.add((ref.constraint_violation > 0, ref.terminal_violation > 0))
        dz, dr = rng.normal(0, 0.2, n), rng.normal(0, 0.2, n)
        assert rel(k.gru_step(x0, u[0], dz, dr),
                   gru.step(fh.params, x0, u[0], dz=dz, dr=dr)) < 1e-14
    assert seen == {(False, False), (False, True), (True, False), (True, True)}


@needs_cc
def test_compiled_candidate_and_governor_test_match_numpy(cert) -> None:
    """The paper's law's evaluate and assess (the governor's feasibility test) give the
    numpy path's numbers with the kernel."""
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint(), kernel="numpy").setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    assert b.kernel is not None
    ref = cert.reference(np.array([0.1, 0.05]))
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    rng = np.random.default_rng(3)
    for _ in range(10):
        u = rng.uniform(-1.2, 1.2, (a.N, a.m))
        ra = a.reference.evaluate(x_hat, u, ref.x_bar, ref.u_bar, 0.02, ref.alpha)
        rb = b.reference.evaluate(x_hat, u, ref.x_bar, ref.u_bar, 0.02, ref.alpha)
        assert rel(rb.x, ra.x) < 1e-13 and rel(rb.cost, ra.cost) < 1e-12
        assert abs(rb.t - ra.t) < 1e-13 and rb.active == ra.active
        assert abs(rb.constraint_violation - ra.constraint_violation) < 1e-12
        assert abs(rb.terminal_violation - ra.terminal_violation) < 1e-12
        va, da = a.reference.assess(x_hat, ra.u, ref.x_bar, 0.02, ref.alpha)
        vb, db = b.reference.assess(x_hat, ra.u, ref.x_bar, 0.02, ref.alpha)
        assert abs(va - vb) < 1e-12 and abs(da - db) < 1e-13


def test_tightened_bounds_are_kept_per_e_o_and_read_only(cert) -> None:
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(), kernel="numpy")
    b1 = fh.tightened_bounds(0.02)
    assert fh.tightened_bounds(0.02) is b1 and not b1.flags.writeable
    b2 = fh.tightened_bounds(0.03)
    assert b2 is not b1 and np.array_equal(
        b2, fh.h - fh.a * 0.03 - fh.b - fh.w_L - fh.Lbo)
    assert np.array_equal(b1, fh.h - fh.a * 0.02 - fh.b - fh.w_L - fh.Lbo)


@needs_cc
def test_portable_build_gives_the_same_derivatives(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """GK_NO_CLONES (no AVX2 clones, no register-blocked products: the path of CPUs without
    AVX2/FMA) against numpy and against the default build."""
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    fh = random_fhocp(20, 15, seed=5, kernel="numpy")
    fast = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2))
    portable = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2),
                        cflags=(*ck.DEFAULT_CFLAGS, "-DGK_NO_CLONES"))
    assert fast is not None and portable is not None and fast.path != portable.path
    nlp = SingleShootingNLP(fh, None)
    nlp.eigen_clip = 1e-2
    rng = np.random.default_rng(1)
    for _ in range(3):
        w = np.concatenate([rng.uniform(-1, 1, fh.N * fh.m), [0.05]])
        p = np.concatenate([rng.uniform(-0.7, 0.7, 2 * fh.n), rng.uniform(-0.9, 0.9, fh.m)])
        lg = rng.normal(0, 1, fh.ng)
        for k in (portable, fast):
            for a, b in zip(k.external("jac_fg")(w, p), nlp.jac_fg(w, p), strict=True):
                assert rel(a, b) < 1e-12
            assert rel(k.external("hess_l")(w, p, 1.0, lg),
                       nlp.hessian_convex(w, p, np.array([1.0]), lg)[0]) < 1e-12


@needs_cc
@pytest.mark.parametrize("portable", [False, True])
def test_clipping_finds_the_eigenpairs_below_the_margin(portable: bool, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """The clipping's own eigenpairs below the margin (Householder to tridiagonal, QL
    without vectors, inverse iteration; N m = 30, below ``LAPACK_EIG_MIN_NU``) against
    numpy's full decomposition (:func:`clip_eigenvalues`, the numpy path's), on Hessian-like
    spectra (0.05 … 6e4) with 0 … 8 eigenvalues below the margin, repeated ones, ones 1e-12
    apart and one on the margin: the same clipped matrix to 1e-14 of its largest entry, and
    never the full decomposition's fallback (``full_eig``)."""
    monkeypatch.setenv("GRU_MPC_KERNEL_CACHE", str(tmp_path))
    fh = random_fhocp(20, 15, seed=1, kernel="numpy")
    flags = (*ck.DEFAULT_CFLAGS, "-DGK_NO_CLONES") if portable else None
    k = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                  LUo=fh.LUo), cflags=flags)
    assert k is not None and "-DGK_LAPACK_EIG" not in k.flags, ck.last_error
    ws = k.workspace()
    rng = np.random.default_rng(3)
    n = k.nw - 1
    below = [[], [-3.0], [-3.0, -0.1, 0.005], [-0.5, -0.5], [-0.5, -0.5 + 1e-12, -0.5],
             [1e-2], [-1e-9, 0.0, 1e-9], list(rng.uniform(-3.0, 1e-2, 8))]
    for low in below:
        q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        lam = np.geomspace(0.05, 6e4, n)
        lam[:len(low)] = low
        H = np.zeros((k.nw, k.nw))
        H[:-1, :-1] = (q * lam) @ q.T
        H[:-1, :-1] = 0.5 * (H[:-1, :-1] + H[:-1, :-1].T)
        H[-1, -1] = 1e-3
        got = ws.clip(H)
        assert np.max(np.abs(got - clip_eigenvalues(H, 1e-2))) < 1e-14 * 6e4, low
        assert np.min(np.linalg.eigvalsh(got[:-1, :-1])) > 1e-2 - 1e-10
    counts = ws.counters()   # every spectrum but the first decomposed (the margin's own:
    assert counts["full_eig"] == 0 and counts["eig"] >= len(below) - 2, counts  # rounding)


@needs_cc
@pytest.mark.parametrize("tracking", [False, True])
def test_every_variant_compiles_without_a_warning(tracking: bool, tmp_path: Path) -> None:
    """The template and its interface header (``gru_fhocp.h``) under ``-Wall -Wextra
    -Werror``, in every build-time variant, for the paper's FHOCP and the tracking one (with
    an input-rate term and a control horizon)."""
    fh = random_fhocp(6, 5, seed=3, kernel="numpy")
    extra = ({"offset_weight": np.ones(2), "du_weight": np.full(2, 0.1), "control_horizon": 3}
             if tracking else {})
    src = ck.library_source(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                              LUo=fh.LUo, **extra)
                             ).replace(ck.PREFIX_PLACEHOLDER, "gk_test_")
    c_file = tmp_path / "kernel.c"
    c_file.write_text(src)
    variants = [[], ["-DGK_BACKWARD"], ["-DGK_LAPACK_EIG"], ["-DGK_TIMERS"], ["-DGK_NO_CLONES"]]
    if not tracking:
        variants.append(["-DGK_CONTRACT"])
    cc = os.environ.get("CC", "gcc")
    for flags in variants:
        out = subprocess.run([cc, "-O1", "-fPIC", "-shared", "-std=gnu99", "-Wall", "-Wextra",
                              "-Werror", *flags, str(c_file), "-o", str(tmp_path / "k.so")],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, (flags, out.stderr[-2000:])
