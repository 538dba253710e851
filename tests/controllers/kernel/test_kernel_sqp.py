"""The SQP inside the compiled kernel (controllers.kernel.kernel_sqp, kernel/qp.c and
sqp.c): its dual active-set QP against the KKT conditions and qpOASES, degenerate and
infeasible QPs, and its FHOCP solves against casadi ``sqpmethod`` from the same starts."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from controllers.errors import DesignError
from controllers.kernel import compiled_kernel as ck
from controllers.kernel.kernel_abi import QpStatus
from controllers.kernel.kernel_sqp import KernelSQP
from controllers.laws.paper.reference import FixedSetpoint
from controllers.ocp.casadi_callbacks import quiet_stdout
from controllers.ocp.fhocp import FHOCP
from tests.controllers.kernel.test_compiled_kernel import needs_cc, random_fhocp, same_start_solves


@pytest.fixture(scope="module")
def kernel() -> ck.Workspace:
    """A small kernel (n = 5, N = 6): the QP's dimensions nw = 13, ng = 20."""
    fh = random_fhocp(5, 6, seed=3)
    assert fh.kernel is not None, fh.kernel_error
    return fh.kernel


def random_qp(rng: np.random.Generator, nw: int, ng: int, dependent: bool = False) -> dict:
    """A strictly convex QP that is feasible by construction, its unconstrained minimum
    outside the feasible set (constraints active at the optimum); ``dependent``: rows that
    are copies and sums of others, and a ± pair sharing a slack column, all tight."""
    M = rng.normal(size=(nw, nw))
    H = M @ M.T / nw + 0.05 * np.eye(nw)
    A = rng.normal(size=(ng, nw))
    x0 = rng.uniform(-0.5, 0.5, nw)
    if dependent:
        A[1] = A[0]
        A[2] = A[0] + A[3]
        A[4] = -A[5]
        A[6, :-1], A[7, :-1] = A[8, :-1], A[8, :-1]
        A[6, -1], A[7, -1] = -1.0, 1.0     # a_k x - t and a_k x + t, as the terminal rows
    ax = A @ x0
    lba, uba = ax - rng.uniform(0.0, 0.3, ng), ax + rng.uniform(0.0, 0.3, ng)
    if dependent:
        lba[:9], uba[:9] = ax[:9] - 1e-3, ax[:9]
    lba[rng.random(ng) < 0.2] = -np.inf
    uba[rng.random(ng) < 0.2] = np.inf
    lbx, ubx = x0 - rng.uniform(0.0, 0.5, nw), x0 + rng.uniform(0.0, 0.5, nw)
    lbx[rng.random(nw) < 0.3] = -np.inf
    g = -H @ (x0 + rng.normal(scale=3.0, size=nw))
    return {"h": H, "g": g, "a": A, "lbx": lbx, "ubx": ubx, "lba": lba, "uba": uba}


def qpoases(q: dict) -> np.ndarray:
    nw, ng = q["a"].shape[1], q["a"].shape[0]
    with quiet_stdout():   # qpOASES' licence banner
        s = ca.conic("s", "qpoases", {"h": ca.Sparsity.dense(nw, nw),
                                      "a": ca.Sparsity.dense(ng, nw)},
                     {"printLevel": "none", "error_on_fail": True})
        return np.array(s(**q)["x"]).ravel()


def kkt_residuals(q: dict, d: np.ndarray, lx: np.ndarray, la: np.ndarray) -> dict:
    """Stationarity, primal feasibility, multiplier signs and complementarity (casadi's
    convention: positive at an upper bound, negative at a lower one)."""
    ad = q["a"] @ d
    out = {"stationarity": np.max(np.abs(q["h"] @ d + q["g"] + q["a"].T @ la + lx))}
    out["feasibility"] = max(0.0, *(q["lba"] - ad), *(ad - q["uba"]), *(q["lbx"] - d),
                             *(d - q["ubx"]))
    sign, slack = 0.0, 0.0
    for lam, v, lo, hi in ((lx, d, q["lbx"], q["ubx"]), (la, ad, q["lba"], q["uba"])):
        for li, vi, loi, hii in zip(lam, v, lo, hi, strict=True):
            if li > 0:
                slack = max(slack, li * (hii - vi))
            elif li < 0:
                slack = max(slack, -li * (vi - loi))
        sign = max(sign, *(np.abs(lam[(lam > 0) & ~np.isfinite(hi)])), 0.0)
        sign = max(sign, *(np.abs(lam[(lam < 0) & ~np.isfinite(lo)])), 0.0)
    out["sign"], out["complementarity"] = sign, slack
    return out


@needs_cc
@pytest.mark.parametrize("dependent", [False, True])
def test_qp_meets_kkt_and_agrees_with_qpoases(kernel: ck.Workspace, dependent: bool) -> None:
    rng = np.random.default_rng(11 + dependent)
    active = 0
    for _ in range(25):
        q = random_qp(rng, kernel.nw, kernel.ng, dependent)
        status, d, lx, la, changes = kernel.qp(q["h"], q["g"], q["a"], q["lbx"], q["ubx"],
                                               q["lba"], q["uba"])
        assert status == QpStatus.OPTIMAL
        res = kkt_residuals(q, d, lx, la)
        assert res["stationarity"] < 1e-9 and res["feasibility"] < 1e-9, res
        assert res["sign"] == 0.0 and res["complementarity"] < 1e-9, res
        assert np.max(np.abs(d - qpoases(q))) < 1e-7   # the primal optimum is unique
        active += int(np.count_nonzero(lx) + np.count_nonzero(la))
        assert changes >= np.count_nonzero(lx) + np.count_nonzero(la)
    assert active > 25        # the tests reach constraints


@needs_cc
def test_qp_reports_infeasibility_and_an_indefinite_hessian(kernel: ck.Workspace) -> None:
    q = random_qp(np.random.default_rng(5), kernel.nw, kernel.ng)
    q["a"][1] = q["a"][0]
    q["lba"][0], q["uba"][0] = 0.0, 1.0
    q["lba"][1], q["uba"][1] = 2.0, 3.0        # the same row in two disjoint intervals
    assert kernel.qp(q["h"], q["g"], q["a"], q["lbx"], q["ubx"], q["lba"], q["uba"])[0] == \
        QpStatus.INFEASIBLE
    q = random_qp(np.random.default_rng(6), kernel.nw, kernel.ng)
    q["h"][0, 0] = -1.0
    assert kernel.qp(q["h"], q["g"], q["a"], q["lbx"], q["ubx"], q["lba"], q["uba"])[0] == \
        QpStatus.NOT_POSITIVE_DEFINITE


@needs_cc
def test_lagrangian_gradient_by_adjoints_matches_the_jacobian(kernel: ck.Workspace) -> None:
    """The stopping test's ∇L (one adjoint sweep through the GRU stages) is ∇f + Jᵀλ_g + λ_x
    of the explicit derivatives."""
    check_lagrangian_gradient(kernel, np.random.default_rng(2), 5)


def check_lagrangian_gradient(ws: ck.Workspace, rng: np.random.Generator, draws: int) -> None:
    """``ws.grad_l`` against ``∇f + Jᵀλ_g + λ_x`` of the explicit derivatives at ``draws``
    random points and multipliers (also test_move_rows')."""
    jac = ws.external("jac_fg")
    for _ in range(draws):
        w = rng.uniform(-1, 1, ws.nw)
        p = rng.normal(scale=0.5, size=ws.npar)
        lx, lg = rng.normal(size=ws.nw), rng.normal(size=ws.ng)
        out = ws.grad_l(w, p, lx, lg)
        _, gf, _, J = (np.array(v) for v in jac(w, p))
        expected = gf.ravel() + J.T @ lg + lx
        assert np.max(np.abs(out - expected)) < 1e-12 * max(1.0, np.max(np.abs(expected)))


@needs_cc
def test_kernel_loop_solves_as_casadi_sqpmethod(cert) -> None:
    """From identical starts the two loops take the same steps as long as the QPs' multipliers
    are unique: same status, the optimum to 1e-9; both check their answers the same way."""
    # 50 iterations: at the default 15 the solves after a set-point change cap, and which of
    # the others do depends on the BLAS kernels the random test problem was certified with
    opts = {"max_iter": 50}
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                               sqp_options={"loop": "casadi", **opts}).setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                               sqp_options={"loop": "kernel", **opts}).setup()
    assert isinstance(b._solver, KernelSQP) and not isinstance(a._solver, KernelSQP)
    solved = 0
    for ra, rb in same_start_solves(a, b, cert, [[0.1, 0.1], [0.0, 0.05], [-0.1, -0.1],
                                                 [0.1, 0.1]], 4):
        assert ra.status == rb.status
        if ra.success:
            solved += 1
            assert abs(ra.iterations - rb.iterations) <= 1
            assert np.max(np.abs(ra.u - rb.u)) < 1e-7
            assert abs(ra.cost - rb.cost) < 1e-9 * (1 + abs(ra.cost))
    assert solved >= 10    # 12 of 16 under every OpenBLAS core type; the rest cap in both
    st = b._buffer[0].stats()
    assert st["t_wall_QP"] > 0 and st["iter_count"] >= 0 and st["return_status"]


def test_kernel_loop_needs_the_kernel(cert) -> None:
    """``kernel="numpy"`` keeps casadi's loop (the numpy callbacks have no C loop); an
    unknown loop is a design error."""
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                kernel="numpy", sqp_options={"loop": "kernel"}).setup()
    assert not isinstance(fh._solver, KernelSQP)
    with pytest.raises(DesignError, match="loop must be"):
        FHOCP.from_certificate(cert, reference=FixedSetpoint(), sqp_options={"loop": "python"})


@needs_cc
def test_kernel_loop_rejects_sqpmethod_options_it_does_not_follow(cert) -> None:
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                sqp_options={"hessian_approximation": "limited-memory"})
    with pytest.raises(DesignError, match="'hessian_approximation' is not supported"):
        fh.setup()
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                sqp_options={"loop": "casadi", "min_iter": 1}).setup()
    assert not isinstance(fh._solver, KernelSQP)


@needs_cc
def test_derivative_reuse_reaches_the_same_optima(cert) -> None:
    """``reuse_step`` (ours): iterations that keep the last Jacobian and Hessian and take the
    adjoint-corrected gradient stop at the same KKT points (the same statuses, the optimum
    to the stopping test's precision) from the same starts; sqpmethod ignores the option."""
    opts = {"max_iter": 50}    # as above: which solves cap at 15 depends on the BLAS
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint(), sqp_options=opts).setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                               sqp_options={"reuse_step": 0.1, **opts}).setup()
    sqp = b._buffer[0]
    solved = reused = 0
    for ra, rb in same_start_solves(a, b, cert, [[0.1, 0.1], [0.0, 0.05], [-0.1, -0.1],
                                                 [0.1, 0.1]], 4):
        assert ra.status == rb.status
        reused += sqp.stats()["derivative_reuses"]
        if ra.success:
            solved += 1
            # the inputs to ~1e-5 where the cost is flat, the cost to its stopping precision
            assert np.max(np.abs(ra.u - rb.u)) < 1e-4
            assert abs(ra.cost - rb.cost) < 1e-7 * (1 + abs(ra.cost))
    assert solved >= 10 and reused > 0
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                sqp_options={"loop": "casadi", "reuse_step": 0.1})
    assert not isinstance(fh.setup()._solver, KernelSQP)


@needs_cc
@pytest.mark.parametrize("max_iter", [4, 6, 15])
def test_derivative_reuse_never_costs_convergence(cert, max_iter: int) -> None:
    """A loop that reused derivatives and ended short of success is discarded, and the solve
    restarts from its initial guess with fresh derivatives: its status is never worse than
    the fresh-derivative solve's, and a restarted answer is that solve's to the bit. Tight
    iteration caps make the reuse loop (more, cheaper iterations) stall where fresh
    derivatives converge, on every BLAS (the fresh solves' counts differ between them)."""
    a = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                               sqp_options={"max_iter": max_iter}).setup()
    b = FHOCP.from_certificate(cert, reference=FixedSetpoint(), sqp_options={"reuse_step": 0.1,
                                                  "max_iter": max_iter}).setup()
    sqp = b._buffer[0]
    restarts = 0
    for ra, rb in same_start_solves(a, b, cert, [[0.1, 0.1], [0.0, 0.05], [-0.1, -0.1],
                                                 [0.1, 0.1]], 4):
        st = sqp.stats()
        assert ra.status == rb.status
        if st["fresh_restarts"]:
            restarts += 1
            assert st["discarded_iterations"] > 0
            # iterations count the discarded loop's too
            assert rb.iterations == ra.iterations + st["discarded_iterations"]
            assert ra.cost == rb.cost
            assert np.array_equal(ra.u, rb.u)
    if max_iter < 15:
        assert restarts > 0


@needs_cc
def test_the_sqp_keeps_its_workspace_alive() -> None:
    """The SQP holds its workspace (the C memory its solves run in): the FHOCP dropped, the
    workspace is freed with the solver, never under it."""
    import gc
    import weakref

    fh = random_fhocp(5, 6, seed=3)
    solver, ws = fh._solver, weakref.ref(fh.kernel)
    assert isinstance(solver, KernelSQP)
    del fh
    gc.collect()
    assert ws() is not None and ws()._finalizer.alive
    solver.solve()    # runs in the live workspace
    del solver
    gc.collect()
    assert ws() is None
