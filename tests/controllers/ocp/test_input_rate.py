"""The input-rate (Δu) penalty of the FHOCP (controllers.ocp.input_rate): its numpy derivatives
against casadi's AD and finite differences, the compiled kernel against numpy in every
variant, the solvers against each other, and du_weight = 0 as the paper's cost, bit for bit."""

from __future__ import annotations

import os
import shutil

import casadi as ca
import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.errors import DesignError
from controllers.kernel import compiled_kernel as ck
from controllers.laws.paper.mpc import PaperMPC
from controllers.laws.paper.reference import FixedSetpoint
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.input_rate import du_cost, du_gradient, du_hessian, du_weights
from controllers.ocp.nlp_single_shooting import SingleShootingNLP
from tests.controllers.kernel.test_compiled_kernel import random_fhocp, rel

needs_cc = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None,
                              reason="no C compiler")


def test_weights_from_a_number_a_list_or_names() -> None:
    assert np.array_equal(du_weights(2, 2), [2.0, 2.0])
    assert np.array_equal(du_weights([1, 0.5, 0], 3), [1.0, 0.5, 0.0])
    assert np.array_equal(du_weights({"qb": 5}, 2, ["qa", "qb"]), [0.0, 5.0])
    for bad, words in ((-1.0, "non-negative"), (float("nan"), "non-negative"),
                       (True, "non-negative"), ([1.0, 2.0, 3.0], "one per input"),
                       ({"qc": 1.0}, "unknown input 'qc' (inputs: qa, qb)"),
                       ({"qa": -2.0}, "du_weight qa=-2.0: expected a non-negative number")):
        with pytest.raises(DesignError) as info:
            du_weights(bad, 2, ["qa", "qb"])
        assert words in str(info.value) and "\n" not in str(info.value)


def test_numpy_term_matches_casadi_ad() -> None:
    """Value, gradient and the constant block-tridiagonal Hessian against casadi's AD."""
    rng = np.random.default_rng(0)
    for N, m in ((1, 1), (5, 2), (7, 3)):
        w = rng.uniform(0.0, 4.0, m)
        u = ca.SX.sym("u", N * m)
        up = ca.SX.sym("up", m)
        prev = [up] + [u[(i - 1) * m:i * m] for i in range(1, N)]
        J = sum(ca.dot(ca.DM(w) * (u[i * m:(i + 1) * m] - prev[i]),
                       u[i * m:(i + 1) * m] - prev[i]) for i in range(N))
        f = ca.Function("f", [u, up], [J, ca.gradient(J, u), ca.hessian(J, u)[0]])
        uv, upv = rng.uniform(-1, 1, (N, m)), rng.uniform(-1, 1, m)
        J_ad, g_ad, H_ad = (np.array(v) for v in f(uv.ravel(), upv))
        assert rel(du_cost(uv, upv, w), J_ad) < 1e-14
        assert rel(du_gradient(uv, upv, w).ravel(), g_ad.ravel()) < 1e-14
        assert rel(du_hessian(N, w), H_ad) < 1e-14


def test_numpy_nlp_derivatives_match_finite_differences() -> None:
    """∇f and the Hessian of the Lagrangian of the single-shooting NLP with the term, against
    central differences of f and of ∇L."""
    fh = random_fhocp(9, 7, seed=3, kernel="numpy", du_weight=[3.0, 0.5])
    assert fh.has_du and fh.npar == 2 * fh.n + 2 * fh.m
    nlp = SingleShootingNLP(fh, None)
    rng = np.random.default_rng(1)
    w = np.concatenate([rng.uniform(-1, 1, fh.N * fh.m), [0.05]])
    p = rng.uniform(-0.5, 0.5, fh.npar)
    lg = rng.normal(0, 1, nlp.ng)
    eps = 1e-6
    E = np.eye(fh.nw)
    _, g = nlp.gradient(w, p)
    g_fd = np.array([(nlp.f(w + eps * e, p)[0] - nlp.f(w - eps * e, p)[0]) / (2 * eps)
                     for e in E])
    assert np.max(np.abs(g - g_fd)) < 1e-7

    def grad_l(wv: np.ndarray) -> np.ndarray:
        return nlp.gradient(wv, p)[1] + nlp.jacobian(wv, p)[1].T @ lg

    H = nlp.hessian(w, p, np.array([1.0]), lg)
    H_fd = np.array([(grad_l(w + eps * e) - grad_l(w - eps * e)) / (2 * eps) for e in E])
    assert np.max(np.abs(H - H_fd)) < 1e-6
    # the term itself: f and ∇f minus those of the same problem without it
    fh0 = random_fhocp(9, 7, seed=3, kernel="numpy")
    nlp0 = SingleShootingNLP(fh0, None)
    u = w[:-1].reshape(fh.N, fh.m)
    up = p[2 * fh.n + fh.m:]
    f1, g1 = nlp.gradient(w, p)
    f0, g0 = nlp0.gradient(w, p[:fh0.npar])
    assert abs(f1 - f0 - du_cost(u, up, fh.du_weight)) < 1e-12
    assert np.max(np.abs((g1 - g0)[:-1] - du_gradient(u, up, fh.du_weight).ravel())) < 1e-12


@needs_cc
@pytest.mark.parametrize(("n", "N", "mode", "m", "p"), [
    (20, 15, "w", 2, 2), (20, 15, "contract", 2, 2), (20, 15, "backward", 2, 2),
    (9, 7, "w", 1, 1), (11, 8, "contract", 3, 2), (10, 12, "backward", 3, 1)])
def test_kernel_matches_numpy_with_the_term(n: int, N: int, mode: str, m: int, p: int,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """f, ∇f, g, ∂g/∂w, both Hessians (raw, clipped), the SQP's ∇L (an adjoint sweep), the
    answer check's cost (assess, assess_w) and the load-time self-test, every variant."""
    monkeypatch.setenv("GRU_MPC_KERNEL_MODE", mode)
    rng = np.random.default_rng(n + N + m)
    dw = rng.uniform(0.5, 20.0, m)
    dw[0] = 0.0 if m > 1 else dw[0]   # a zero weight among nonzero ones
    fh = random_fhocp(n, N, seed=n + N, m=m, p=p, kernel="numpy", du_weight=dw)
    lib = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                    LUo=fh.LUo, du_weight=fh.du_weight))
    assert lib is not None, ck.last_error
    assert lib.npar == fh.npar == 2 * n + 2 * m
    k = lib.workspace()
    nlp = SingleShootingNLP(fh, None)
    nlp.eigen_clip = 1e-2
    for _ in range(4):
        w = np.concatenate([rng.uniform(-1.2, 1.2, N * m), [0.05]])
        pv = np.concatenate([rng.uniform(-0.7, 0.7, 2 * n), rng.uniform(-0.9, 0.9, 2 * m)])
        lg = rng.normal(0, 1, nlp.ng) * rng.choice([1e-3, 1.0, 100.0], nlp.ng)
        lx = rng.normal(0, 1, fh.nw)
        for a, b in zip(lib.external("jac_fg")(w, pv), nlp.jac_fg(w, pv), strict=True):
            assert rel(a, b) < 1e-12
        assert rel(lib.external("fg")(w, pv)[0], nlp.f(w, pv)[0]) < 1e-12
        assert rel(lib.external("hess_raw")(w, pv, 1.0, lg),
                   nlp.hessian(w, pv, np.array([1.0]), lg)) < 1e-12
        assert rel(lib.external("hess_l")(w, pv, 1.0, lg),
                   nlp.hessian_convex(w, pv, np.array([1.0]), lg)[0]) < 1e-12
        _, gf, _, J = nlp.jac_fg(w, pv)
        assert rel(k.grad_l(w, pv, lx, lg), gf + J.T @ lg + lx) < 1e-12
        x_bar, u_bar, up = pv[n:2 * n], pv[2 * n:2 * n + m], pv[2 * n + m:]
        u = np.clip(w[:-1].reshape(N, m), -1.0, 1.0)
        x = nlp.shoot.rollout(pv[:n], u, derivatives=False).x
        bounds = fh.tightened_bounds(0.01)
        _, out = k.assess(pv[:n], u, x_bar, u_bar, bounds, 0.3, up)
        assert rel(out.cost, fh.reference.cost(x, u, x_bar, u_bar, u_prev=up)) < 1e-12
        _, _, out_w, _ = k.assess_w(w, pv, bounds, 0.3)
        assert rel(out_w.cost, out.cost) < 1e-14
    assert nlp.self_test(k, 1e-2) < ck.KERNEL_SELF_TEST_TOL


@needs_cc
def test_the_self_test_sees_the_term() -> None:
    """A kernel whose input-rate weights differ from the problem's fails the load-time
    self-test (so a wrong term would never be used)."""
    fh = random_fhocp(9, 7, seed=4, kernel="numpy", du_weight=[2.0, 1.0])
    wrong = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                      LUo=fh.LUo, du_weight=np.array([2.0, 1.5])))
    right = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                      LUo=fh.LUo, du_weight=fh.du_weight))
    nlp = SingleShootingNLP(fh, None)
    assert nlp.self_test(right.workspace(), 1e-2) < ck.KERNEL_SELF_TEST_TOL
    assert nlp.self_test(wrong.workspace(), 1e-2) > 1e-3


@needs_cc
def test_zero_weight_is_the_paper_cost_bit_for_bit(cert) -> None:
    """du_weight = 0: the same kernel library as without the option (HAS_DU 0, no u_{−1} in
    p), and identical solves whatever u_prev is passed."""
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint(), du_weight=0.0).setup()
    assert not b.has_du and b.npar == 2 * b.n + b.m
    assert a.kernel is not None and a.kernel.path == b.kernel.path
    src = ck.generate_source(ck.KernelProblem(a.params, a.N, a.Q, a.R, a.DUo, a.s, 1e-2,
                                              a.LUo, np.zeros(a.m)))
    assert "#define HAS_DU 0" in src and "static double DW[" not in src
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    for y in ([0.1, 0.1], [0.0, 0.05]):
        ref = cert.reference(np.array(y))
        ra = a.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
        rb = b.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, u_prev=np.array([0.7, -0.7]))
        assert np.array_equal(ra.u, rb.u) and ra.cost == rb.cost
        assert (ra.status, ra.iterations) == (rb.status, rb.iterations)
        x_hat = a.rollout(x_hat, ra.u)[1]


@needs_cc
def test_the_solvers_agree_on_the_optimum_with_the_term(cert) -> None:
    """Kernel SQP, numpy SQP (casadi sqpmethod), IPOPT on the single-shooting callbacks and
    plain multiple shooting (casadi AD of the term) reach the same optimum."""
    dw = np.array([10.0, 3.0])
    solvers = {
        "kernel": FHOCP.from_certificate(cert, reference=FixedSetpoint(), du_weight=dw),
        "numpy": FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                        du_weight=dw, kernel="numpy"),
        "ipopt": FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                        du_weight=dw, solver="ipopt",
                                        ipopt_options={"tol": 1e-10, "max_iter": 500}),
        "multiple": FHOCP.from_certificate(cert, reference=FixedSetpoint(), du_weight=dw,
                                           formulation="multiple-shooting",
                                           ipopt_options={"tol": 1e-10}),
    }
    assert solvers["kernel"].setup().kernel is not None
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    ref = cert.reference(np.array([0.1, 0.05]))
    u_prev = np.array([0.3, -0.2])
    res = {k: fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False,
                       u_prev=u_prev) for k, fh in solvers.items()}
    assert all(r.success for r in res.values()), {k: r.status for k, r in res.items()}
    best = res["kernel"]
    assert np.max(np.abs(res["numpy"].u - best.u)) < 1e-8
    for k in ("ipopt", "multiple"):
        assert np.max(np.abs(res[k].u - best.u)) < 1e-4, k
        assert abs(res[k].cost - best.cost) < 1e-6 * (1 + best.cost), k
    # the term is in the reported cost, at the u_{−1} given
    plain = FHOCP.from_certificate(cert, reference=FixedSetpoint()).reference.cost(
        best.x, best.u, ref.x_bar, ref.u_bar)
    assert best.cost == pytest.approx(plain + du_cost(best.u, u_prev, dw), rel=1e-12)


def test_a_larger_weight_keeps_the_first_input_nearer_the_previous_one(cert) -> None:
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    ref = cert.reference(np.array([0.1, 0.1]))
    u_prev = ref.u_bar - 0.3
    moves = []
    for dw in (0.0, 1.0, 10.0, 100.0):
        fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(), du_weight=dw, kernel="numpy",
                                    sqp_options={"max_iter": 200})
        r = fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, u_prev=u_prev)
        assert r.success, r.status
        moves.append(float(np.max(np.abs(r.u[0] - u_prev))))
    assert moves == sorted(moves, reverse=True) and moves[-1] < 0.5 * moves[0]


def test_the_controller_passes_the_applied_input(cert) -> None:
    """RobustMPC: u_{−1} of each solve is the input applied at the previous step (ū at the
    first), and the step's cost includes the term at it."""
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(), du_weight=5.0, kernel="numpy")
    mpc = PaperMPC(fh)
    ref = cert.reference(np.array([0.1, 0.05]))
    mpc.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    assert mpc.u_prev is None
    applied = []
    for _ in range(3):
        u_prev = ref.u_bar if not applied else applied[-1]
        rec = mpc.make_step(x_hat, 0.02)
        assert np.array_equal(fh._buffer[2]["p"][2 * fh.n + fh.m:], u_prev)
        r = rec.result
        want = fh.reference.cost(r.x, r.u, ref.x_bar, ref.u_bar, u_prev=u_prev)
        assert r.cost == pytest.approx(want, rel=1e-12)
        applied.append(rec.u)
        assert np.array_equal(mpc.u_prev, rec.u)
        x_hat = fh.rollout(x_hat, r.u)[1]
    mpc.reset()
    assert mpc.u_prev is None
