"""The FHOCP with the tracking law (controllers.laws.tracking.reference): its steady state, its
exact derivatives, the compiled kernel's HAS_ASS variant against the numpy twin, and the
tracking law in the GRU world (any set-point tracked to the closest admissible steady state,
offset-free under a constant output disturbance)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.certification import certificates as certs
from controllers.equilibrium import equilibrium, jacobians
from controllers.errors import DesignError
from controllers.gru import output, step
from controllers.laws.tracking.mpc import DisturbanceFilter, TrackingMPC
from controllers.laws.tracking.reference import ArtificialSteadyState, steady_output_bounds
from controllers.model import DEFAULT_MODEL, GRUModel
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.steady_state import steady_state
from tests.controllers.random_gru import random_gru_model


def _fhocp(model: GRUModel, N: int = 6, du: float = 0.1, control_horizon: object = None,
           **options: object) -> FHOCP:
    cert = certs.compute_certificate(model, N=N, gain_scale=0.0, w_y_bar=0.01)
    ass = ArtificialSteadyState(1e3, 0.05, control_horizon=control_horizon)  # bad: refused
    return FHOCP.from_certificate(cert, reference=ass, du_weight=du, **options)


def _point(fh: FHOCP, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n, m = fh.n, fh.m
    us = rng.uniform(-0.5, 0.5, m)
    xs, _, ok = steady_state(fh.params, us, np.zeros(n))
    assert ok
    wv = np.concatenate([rng.uniform(-1, 1, fh.reference.control_horizon * m), us + 0.01, [0.03]])
    pv = np.concatenate([xs + rng.normal(0, 0.05, n), xs + rng.normal(0, 1e-3, n),
                         rng.uniform(-0.5, 0.5, fh.npar - 2 * n)])
    return wv, pv


def test_the_steady_state_is_the_fixed_point_and_its_derivative_the_implicit_one() -> None:
    model = random_gru_model(3, n=8)
    P = model.params
    us = np.array([0.3, -0.2])
    xs, Xs, ok = steady_state(P, us, np.zeros(8))
    assert ok and np.max(np.abs(step(P, xs, us) - xs)) < 1e-13
    eps = 1e-6
    for j in range(2):
        e = np.zeros(2)
        e[j] = eps
        fd = (steady_state(P, us + e, xs)[0] - steady_state(P, us - e, xs)[0]) / (2 * eps)
        assert np.max(np.abs(fd - Xs[:, j])) < 1e-7
    A, _ = jacobians(P, xs, us)
    assert np.max(np.abs(np.linalg.eigvals(A))) < 1


@pytest.mark.parametrize(("du", "M"), [(0.0, None), (0.1, None), (0.1, 3), (0.0, 1)])
def test_the_numpy_derivatives_are_exact(du: float, M: int | None) -> None:
    """Against central differences, with every input free and with a control horizon M
    (the tail held at u_s: the chain rule through the expanded vector)."""
    fh = _fhocp(random_gru_model(4, n=8), du=du, control_horizon=M)
    nlp = fh.numpy_nlp()
    wv, pv = _point(fh, 1)
    lg = np.random.default_rng(2).normal(0, 1, fh.ng)
    _, grad = nlp.gradient(wv, pv)
    _, J = nlp.jacobian(wv, pv)
    H = nlp.hessian(wv, pv, np.array([1.0]), lg)
    eps = 1e-6
    for i in range(fh.nw):
        e = np.zeros(fh.nw)
        e[i] = eps
        fd = (nlp.f(wv + e, pv)[0] - nlp.f(wv - e, pv)[0]) / (2 * eps)
        assert abs(fd - grad[i]) <= 1e-6 * max(1.0, abs(grad[i]))
        Jfd = (nlp.g(wv + e, pv)[0] - nlp.g(wv - e, pv)[0]) / (2 * eps)
        assert np.max(np.abs(Jfd - J[:, i])) < 1e-6

        def grad_l(w: np.ndarray) -> np.ndarray:
            return nlp.gradient(w, pv)[1] + nlp.jacobian(w, pv)[1].T @ lg

        Hfd = (grad_l(wv + e) - grad_l(wv - e)) / (2 * eps)
        assert np.max(np.abs(Hfd - H[:, i])) < 1e-5 * max(1.0, np.max(np.abs(H)))


@pytest.mark.parametrize(("m", "p", "du", "M"), [(2, 2, 0.1, None), (1, 1, 0.0, None),
                                                  (3, 2, 0.1, None), (2, 2, 0.1, 3),
                                                  (1, 1, 0.0, 1), (3, 2, 0.1, 5)])
@pytest.mark.parametrize("mode", ["w", "backward"])
def test_the_compiled_kernel_agrees_with_the_numpy_twin(m: int, p: int, du: float,
                                                         M: int | None, mode: str,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """f, ∇f, g, ∂g/∂w and the clipped Hessian, in both Hessian modes a control horizon
    runs in (W-mode and backward condensing), the tail of u_s's included."""
    monkeypatch.setenv("GRU_MPC_KERNEL_MODE", mode)
    fh = _fhocp(random_gru_model(5, n=6, m=m, p=p), du=du, control_horizon=M).setup()
    assert fh.kernel is not None, fh.kernel_error
    assert fh.reference.control_horizon == fh.kernel.kernel.M
    assert fh.numpy_nlp().self_test(fh.kernel, fh.sqp_options["hessian_eigen_clip"]) < 1e-9


def test_the_kernels_steady_state_derivative_holds_when_its_lu_pivots() -> None:
    """X_s = (I − A_s)^{-1} B_s where the LU of I − A_s swaps rows after its first column
    (a model whose candidate state couples more strongly than it keeps: reset gates open,
    a rotation in U_h). A default-trained furnace model met this: the kernel failed its
    self-test and the numpy derivatives made `cosim tune` take minutes."""
    import scipy.linalg

    from tests.controllers.kernel.test_compiled_kernel import random_fhocp

    n = 6
    fh = random_fhocp(n, 8, seed=3, du_weight=0.1,
                      reference=ArtificialSteadyState(1e3, 0.05, ys_bounds=np.full(4, 0.9)))
    rotation = np.roll(np.eye(n), 1, axis=1)
    fh.params["U_h"] = 1.5 * (rotation - rotation.T)
    fh.params["b_r"] = np.full(n, 4.0)
    us = np.array([0.3, -0.2])
    xs, _, ok = steady_state(fh.params, us, np.zeros(n))
    pivots = scipy.linalg.lu_factor(np.eye(n) - jacobians(fh.params, xs, us)[0])[1]
    assert ok and np.any(pivots[1:] != np.arange(1, n))   # a swap after the first column
    fh.setup()
    assert fh.kernel is not None, fh.kernel_error
    assert fh.numpy_nlp().self_test(fh.kernel, fh.sqp_options["hessian_eigen_clip"]) < 1e-9


@pytest.fixture(scope="module")
def fourtank() -> tuple[GRUModel, FHOCP]:
    model = GRUModel.load(DEFAULT_MODEL)
    cert = certs.compute_certificate(model, N=15, gain_scale=0.0)
    fh = FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1e5, 0.0199), du_weight=0.1,
                                sqp_options={"max_iter": 100})
    return model, fh.setup()


def _closed_loop(model: GRUModel, fh: FHOCP, y0: np.ndarray, y_ref: np.ndarray,
                 steps: int, bias: np.ndarray) -> tuple[TrackingMPC, np.ndarray, list[bool]]:
    """The tracking law on the GRU model as the plant, its output offset by ``bias``; the
    observer runs the model (zero gains), ``d̂`` from the filter (β = 0.2)."""
    P = model.params
    x, u = equilibrium(model, y0)[:2]
    x_hat = x.copy()
    law = TrackingMPC(fh)
    law.start(u, x)
    dist = DisturbanceFilter(0.2, fh.p)
    fallbacks = []
    y = output(P, x) + bias
    for _ in range(steps):
        y = output(P, x) + bias
        d = dist.update(y, output(P, x_hat))
        rec = law.make_step(x_hat, 0.02, y_ref - d)
        fallbacks.append(rec.fallback)
        x, x_hat = step(P, x, rec.u), step(P, x_hat, rec.u)
    return law, y, fallbacks


def test_the_law_removes_a_constant_output_offset(fourtank) -> None:
    model, fh = fourtank
    y0, y1 = model.normalize_y(np.array([0.8, 0.8])), model.normalize_y(np.array([1.0, 0.9]))
    bias = np.array([0.03, -0.02])
    _law, y, fallbacks = _closed_loop(model, fh, y0, y1, 400, bias)
    assert not any(fallbacks[1:])
    assert np.max(np.abs(y - y1)) < 1e-4     # the measured output at the set-point


def test_an_inadmissible_setpoint_is_tracked_to_the_closest_admissible_steady_state(
        fourtank) -> None:
    model, fh = fourtank
    y0 = model.normalize_y(np.array([1.0, 1.0]))
    y_ref = model.normalize_y(np.array([1.9, 1.0]))     # outside Y_s (h1 above ~1.5 m)
    law, y, fallbacks = _closed_loop(model, fh, y0, y_ref, 300, np.zeros(2))
    assert not any(fallbacks[1:])
    ys = output(model.params, law.x_s)
    rows = fh.LUo @ law.x_s - (fh.reference.ys_bounds - fh.Lbo)
    assert np.max(rows) < 1e-7                          # y_s in Y_s, on its boundary
    assert np.max(rows) > -1e-4
    assert abs(ys[1] - y_ref[1]) < 1e-3                 # the reachable coordinate is held
    assert np.max(np.abs(y - ys)) < 1e-3                # and the plant settles at y_s


def test_steady_output_bounds_are_the_alpha_c_level_set() -> None:
    model = random_gru_model(4, n=8)
    cert = certs.compute_certificate(model, N=6, gain_scale=0.0, w_y_bar=0.01)
    rhs = steady_output_bounds(cert, 0.05)
    y = np.zeros(cert.L.shape[1])
    assert np.all(cert.L @ y <= rhs) == (cert.alpha(y) >= 0.05)


@pytest.mark.parametrize(("m", "p", "M"), [(1, 1, None), (3, 2, None), (2, 2, 4), (1, 1, 1)])
def test_the_law_reaches_a_reachable_setpoint_on_any_plant_shape(m: int, p: int,
                                                                  M: int | None) -> None:
    """SISO, 2×2 and 3 inputs × 2 outputs (random δISS GRUs as their own plants), every
    input free or a control horizon M: a set-point that is a steady output (of u = 0.3) is
    reached, with no fallback after the first step; under a control horizon every plan
    holds u_s from stage M on (the shifted plan stays a candidate of the same form)."""
    model = random_gru_model(7, n=6, m=m, p=p)
    P = model.params
    fh = _fhocp(model, N=10, du=0.1, control_horizon=M).setup()
    assert fh.kernel is not None, fh.kernel_error
    target, _, _ = steady_state(P, np.full(m, 0.3), np.zeros(6))
    y_ref = output(P, target)
    assert np.all(fh.LUo @ target <= fh.reference.ys_bounds - fh.Lbo)   # inside Y_s
    x, _, _ = steady_state(P, np.zeros(m), np.zeros(6))
    law = TrackingMPC(fh)
    law.start(np.zeros(m), x)
    fallbacks = []
    for _ in range(150):
        rec = law.make_step(x, 0.0, y_ref)
        fallbacks.append(rec.fallback)
        x = step(P, x, rec.u)
        assert law.plan is not None and law.u_s is not None
        M_ = fh.reference.control_horizon
        assert np.array_equal(law.plan[M_:], np.tile(law.u_s, (fh.N - M_, 1)))
    assert not any(fallbacks[1:])
    assert np.max(np.abs(output(P, x) - y_ref)) < 1e-4


def test_a_control_horizon_is_the_full_problem_restricted_to_a_held_tail() -> None:
    """The layout (u_i = u_s for i ≥ M), the warm start's shift (the last free input takes
    u_s's value) and bad values."""
    fh = _fhocp(random_gru_model(4, n=8), N=6, control_horizon=2)
    m = fh.m
    assert fh.nw == 2 * m + m + 1 and fh.it == 3 * m
    assert fh.iu[:2].ravel().tolist() == list(range(2 * m))
    ius = fh.reference.ius
    assert all(row.tolist() == ius.tolist() for row in fh.iu[2:])
    w = np.arange(fh.nw, dtype=float)
    shifted = w[fh.reference.perm_x]
    assert shifted[fh.iu[0]].tolist() == w[fh.iu[1]].tolist()   # u_0 <- u_1
    assert shifted[fh.iu[1]].tolist() == w[ius].tolist()        # u_1 <- u_2 = u_s
    assert shifted[ius].tolist() == w[ius].tolist()
    full = _fhocp(random_gru_model(4, n=8), N=6)
    assert full.reference.control_horizon == 6 and full.nw == 6 * m + m + 1
    for bad in (0, 7, 2.0, True):
        with pytest.raises(DesignError, match=r"control_horizon must be an integer in 1\.\.N"):
            _fhocp(random_gru_model(4, n=8), N=6, control_horizon=bad)


def test_the_relative_dual_test_ends_converged_solves_as_converged() -> None:
    """The terminal rows' multipliers reach 10⁵: with sqpmethod's absolute dual test the
    solves of a set-point step (h from (0.78, 1.27) m towards (0.97, 0.62) m) end at KKT
    points as Search_Direction_Becomes_Too_Small, with the relative one (SQP_OVERRIDES) as
    optimal, at the same inputs, in fewer iterations."""
    model = GRUModel.load(DEFAULT_MODEL)
    cert = certs.compute_certificate(model, N=15, gain_scale=0.0)
    y0, y1 = model.normalize_y(np.array([0.78, 1.27])), model.normalize_y(np.array([0.97, 0.62]))
    runs = {}
    for relative in (False, True):
        fh = FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1e5, 0.0199),
                                    du_weight=0.1, sqp_options={"tol_du_relative": relative})
        law = _closed_loop(model, fh.setup(), y0, y1, 60, np.zeros(2))[0]
        runs[relative] = (np.array([r.u for r in law.records]),
                          [r.result.status for r in law.records],
                          sum(r.result.iterations for r in law.records))
    (u_abs, st_abs, it_abs), (u_rel, st_rel, it_rel) = runs[False], runs[True]
    assert st_abs.count("Search_Direction_Becomes_Too_Small") >= 20
    assert "Search_Direction_Becomes_Too_Small" not in st_rel
    assert st_rel.count("optimal") >= 50
    assert np.max(np.abs(u_rel - u_abs)) < 1e-3
    assert it_rel < 0.8 * it_abs


def test_sqpmethod_ignores_the_kernels_relative_dual_test() -> None:
    fh = _fhocp(random_gru_model(4, n=6), N=4, sqp_options={"loop": "casadi"}).setup()
    assert fh.sqp_options["tol_du_relative"] is True        # SQP_OVERRIDES
    wv, pv = _point(fh, 3)
    n = fh.n
    res = fh.solve(pv[:n], 0.0, pv[2 * n:2 * n + fh.p], wv[fh.iu], wv[fh.reference.ius],
                   pv[n:2 * n])
    assert np.all(np.isfinite(res.u)) and res.iterations >= 1


@pytest.mark.parametrize(("m", "p", "du", "M"), [(2, 2, 0.1, None), (1, 1, 0.0, 1),
                                                  (3, 2, 0.1, 3)])
def test_the_compiled_answer_check_is_the_numpy_check(m: int, p: int, du: float,
                                                      M: int | None) -> None:
    """The kernel's check of an answer (one call: plain rollout, x_s(u_s) with its fixed
    point tested, the tracking cost and every residual) against the numpy FHOCP's check,
    and the terminal gap that initialises t."""
    model = random_gru_model(6, n=6, m=m, p=p)
    fh = _fhocp(model, du=du, control_horizon=M).setup()
    ref = _fhocp(model, du=du, control_horizon=M, kernel="numpy")
    assert fh.kernel is not None and ref.kernel is None
    n = fh.n
    for seed in range(4):
        wv, pv = _point(fh, seed)
        wv[fh.reference.ius] += 0.5 * (seed == 3)              # u_s beyond the box: clipped by both
        x_hat, xs0, r = pv[:n], pv[n:2 * n], pv[2 * n:2 * n + fh.p]
        up = pv[2 * n + fh.p:] if fh.has_du else None
        e_o = 0.01 * seed
        got = fh.reference._check_compiled(wv, pv, e_o, "s")
        want = ref.reference.evaluate(x_hat, wv[fh.iu], wv[fh.reference.ius], e_o, r, xs0, up, "s")
        assert np.max(np.abs(got.x - want.x)) < 1e-12
        assert np.max(np.abs(got.x_s - want.x_s)) < 1e-12
        assert np.array_equal(got.u, want.u) and np.array_equal(got.u_s, want.u_s)
        assert abs(got.cost - want.cost) < 1e-12 * max(1.0, abs(want.cost))
        for key in ("constraint_violation", "terminal_violation", "t"):
            assert abs(getattr(got, key) - getattr(want, key)) < 1e-12, key
        assert got.active == want.active and got.defect < 1e-14
        gap = fh.kernel.terminal_gap(wv, pv)
        x_s = want.x_s if seed < 3 else steady_state(fh.params, wv[fh.reference.ius], xs0)[0]
        assert abs(gap - np.max(np.abs(ref.simulate(x_hat, wv[fh.iu])[-1] - x_s))) < 1e-12


def test_derivative_reuse_keeps_the_answers_with_fewer_derivatives() -> None:
    """The kernel SQP's derivative reuse (``reuse_step``, on by default in SQP_OVERRIDES):
    along a set-point step the same statuses and inputs to the stopping test's precision,
    with fewer evaluations of the sensitivities and the Hessian."""
    model = GRUModel.load(DEFAULT_MODEL)
    cert = certs.compute_certificate(model, N=15, gain_scale=0.0)
    y0, y1 = model.normalize_y(np.array([0.78, 1.27])), model.normalize_y(np.array([0.97, 0.62]))
    runs = {}
    for options in ({"reuse_step": 0.0}, {}):
        fh = FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1e4, 0.0199),
                                    du_weight=0.05, sqp_options=options).setup()
        sqp, trigger, ins, outs = fh._buffer
        reuses: list[int] = []

        def counted(sqp=sqp, trigger=trigger, reuses=reuses) -> None:
            trigger()
            reuses.append(sqp.stats()["derivative_reuses"])

        fh._buffer = (sqp, counted, ins, outs)
        law = _closed_loop(model, fh, y0, y1, 60, np.zeros(2))[0]
        iterations = sum(r.result.iterations for r in law.records)
        runs[fh.sqp_options["reuse_step"]] = (np.array([r.u for r in law.records]),
                                              [r.result.status for r in law.records],
                                              iterations - sum(reuses), sum(reuses))
    (u0, st0, fresh0, re0), (u1, st1, fresh1, re1) = runs[0.0], runs[0.1]
    assert re0 == 0 and re1 > 0
    assert st1 == st0 and st1.count("optimal") >= 55
    assert np.max(np.abs(u1 - u0)) < 1e-4
    assert fresh1 < 0.8 * fresh0
