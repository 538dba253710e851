"""The FHOCP ``eq:optimization`` (controllers.mpc): optimum, constraints, recursive
feasibility in closed loop (``th:feasibility-stability``) and the fallback path."""

import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.gru import output, simulate, step
from controllers.laws.paper.mpc import PaperMPC
from controllers.laws.paper.reference import FixedSetpoint
from controllers.observer import GRUObserver
from controllers.ocp.fhocp import FHOCP, FHOCPData
from controllers.ocp.solver_settings import FEAS_TOL
from cosim.adapters.gru_plant import GRUPlant
from tests.controllers.random_gru import N


def make(cert, max_iter=200, **kw):
    kw.setdefault("ipopt_options", {"max_iter": max_iter})
    return FHOCP.from_certificate(cert, reference=FixedSetpoint(), **kw).setup()


@pytest.fixture(scope="module", params=["ipopt", "sqp"])
def fast(cert, request):
    """The fast single-shooting FHOCP: with IPOPT, and with the default solver (SQP on the
    compiled kernel when a C compiler is found)."""
    if request.param == "sqp":
        return FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                      sqp_options={"max_iter": 200}).setup()
    return make(cert)


@pytest.fixture(scope="module")
def reference(cert):
    return make(cert, formulation="multiple-shooting",
                ipopt_options={"tol": 1e-11, "constr_viol_tol": 1e-11, "max_iter": 3000})


def start_state(model, y):
    x, _ = equilibrium(model, y)
    return x


@pytest.mark.parametrize("y0, y_bar", [((0.0, 0.0), (0.1, 0.1)),
                                       ((0.15, -0.1), (0.0, 0.05)),
                                       ((-0.1, 0.15), (0.1, 0.1))])
def test_optimum_matches_tight_reference(model, cert, fast, reference, y0, y_bar):
    x_hat = start_state(model, np.array(y0))
    ref = cert.reference(np.array(y_bar))
    fast.reset_warm_start()
    a = fast.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    # the reference starts from the fast answer and from ū: the better of the two local optima
    b1 = reference.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, u_init=a.u, warm=False)
    b2 = reference.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert a.success and b1.success, (a.status, b1.status)
    best = min(b.cost for b in (b1, b2) if b.success)
    assert a.cost == pytest.approx(b1.cost, rel=1e-6, abs=1e-9)
    assert a.cost <= best * (1 + 1e-6) + 1e-9
    # independent checks of the answer (numpy rollout, not the solver's numbers)
    x, xi = simulate(model.params, x_hat, a.u)
    np.testing.assert_allclose(x, a.x, atol=1e-12)
    ub = fast.tightened_bounds(0.02)
    assert np.all(xi @ cert.L.T + cert.w_L <= cert.h - cert.a[:N] * 0.02 - cert.b[:N] + 1e-7)
    assert np.all(xi @ cert.L.T <= ub + cert.L @ model.params["b_o"] + 1e-7)
    assert np.max(np.abs(a.u)) <= 1 + 1e-9
    assert np.max(np.abs(x[N] - ref.x_bar)) <= ref.alpha + 1e-7
    assert a.constraint_violation <= FEAS_TOL and a.terminal_violation <= FEAS_TOL
    assert a.defect <= 1e-8


def test_constraints_become_active_and_hold(model, cert, fast):
    """A set-point near the tightened bound: output constraints active, never violated."""
    x_hat = start_state(model, np.array([-0.1, -0.1]))
    y_bar = np.array([0.12, 0.12])
    assert cert.assumption_1(y_bar)
    ref = cert.reference(y_bar)
    res = fast.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert res.success
    assert res.active >= 1
    lhs = res.x[:N] @ fast.LUo.T
    assert np.all(lhs <= fast.tightened_bounds(0.02) + 1e-7)


def test_infeasible_initial_constraint_is_reported_without_solving(model, cert, fast):
    x_hat = start_state(model, np.array([0.0, 0.0]))
    ref = cert.reference(np.array([0.1, 0.1]))
    huge = 1.0  # a_0 ê_o alone exceeds the output range: the i = 0 row fails at x̂
    assert fast.check_x0(x_hat, huge) > 0
    res = fast.solve(x_hat, huge, ref.x_bar, ref.u_bar, ref.alpha)
    assert res.status == "infeasible_x0" and not res.success
    assert res.iterations == 0


def test_recursive_feasibility_closed_loop_with_bounded_noise(model, cert):
    """th:feasibility-stability: plant = model, ‖w_y‖∞ ≤ w̄_y, observer with ê_o: the FHOCP
    stays feasible at every step and the outputs satisfy the constraints."""
    y_bar = np.array([0.1, 0.1])
    assert cert.ok(y_bar)
    ref = cert.reference(y_bar)
    ctrl = PaperMPC(make(cert))
    ctrl.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    plant = GRUPlant(model, y0=model.denormalize_y(np.array([0.0, 0.05])),
                     w_y_max=cert.w_y_bar, seed=3)
    obs = GRUObserver.from_certificate(cert)
    # ‖x_0 − x̂_0‖∞ ≤ ê_o,0: start the observer inside the assumed error ball
    obs.reset(x0=plant.x + np.random.default_rng(0).uniform(-1, 1, model.n) * cert.e_o0 * 0.9)
    worst = -np.inf
    for _ in range(3 * N):
        y = plant.y_norm()
        worst = max(worst, float(np.max(cert.L @ y - cert.h)))
        rec = ctrl.make_step(obs.x_hat, obs.e_o)
        assert rec.result.success, rec.result.status
        assert not rec.fallback
        obs.make_step(rec.u, y)
        plant.u = rec.u
        plant.step(0.0, model.Ts)
    assert worst <= 0.0
    assert ctrl.summary()["fallbacks"] == 0
    # the loop converged towards the set-point (ISS, small w_y)
    assert np.max(np.abs(output(model.params, plant.x) - y_bar)) < 0.05


def test_fallback_applies_shifted_previous_solution_when_solver_raises(model, cert):
    fh = make(cert)
    ctrl = PaperMPC(fh)
    ref = cert.reference(np.array([0.1, 0.1]))
    ctrl.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    x = start_state(model, np.array([0.0, 0.05]))
    first = ctrl.make_step(x, 0.02)
    assert first.result.success and not first.fallback
    x = step(model.params, x, first.u)

    def broken() -> None:
        raise RuntimeError("solver crashed")

    buf, _, ins, outs = fh._buffer
    fh._buffer = (buf, broken, ins, outs)
    second = ctrl.make_step(x, 0.02)
    assert second.fallback and second.result.status.startswith("solver_error")
    np.testing.assert_array_equal(second.u, first.result.u[1])
    np.testing.assert_array_equal(ctrl.plan[-1], ref.u_bar)
    third = ctrl.make_step(step(model.params, x, second.u), 0.02)
    np.testing.assert_array_equal(third.u, first.result.u[2])
    s = ctrl.summary()
    assert s["fallbacks"] == 2 and s["failures"] == 2
    assert s["failures_by_status"] == {"solver_error": 2}


@pytest.mark.parametrize("options", [{"ipopt_options": {"max_iter": 0}},
                                     {"time_budget": 0.0}])
def test_fallback_when_solver_fails(model, cert, options):
    ctrl = PaperMPC(make(cert, **options), accept_suboptimal=False)
    ref = cert.reference(np.array([0.1, 0.1]))
    ctrl.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    x = start_state(model, np.array([0.0, 0.05]))
    rec = ctrl.make_step(x, 0.02)
    assert rec.fallback and not rec.result.success
    np.testing.assert_array_equal(rec.u, ref.u_bar)  # no previous solution: ū
    assert ctrl.summary()["fallbacks"] == 1


def test_residual_check_rejects_wrong_answers(model, cert):
    """A solver that reports success with a wrong answer is caught by the residual checks."""
    fh = make(cert)
    ref = cert.reference(np.array([0.1, 0.1]))
    x = start_state(model, np.array([-0.15, 0.15]))
    buf, real, ins, outs = fh._buffer

    def lying() -> None:
        real()
        assert buf.stats()["success"]
        outs["x"][:] = 1.0  # u = 1, t = 1: violates t ≤ α

    fh._buffer = (buf, lying, ins, outs)
    res = fh.solve(x, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert not res.success
    assert res.terminal_violation > 0 or res.constraint_violation > 0


def test_capped_feasible_iterate_is_applied_as_suboptimal(model, cert):
    """Suboptimal MPC: an iteration-capped solve whose iterate is feasible and no costlier
    than the shifted candidate is applied (not the candidate); otherwise the fallback."""
    ref = cert.reference(np.array([0.1, 0.1]))
    x = start_state(model, np.array([0.0, 0.05]))
    ctrl = PaperMPC(make(cert, max_iter=2))
    ctrl.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    rec = ctrl.make_step(x, 0.02)
    assert not rec.result.success and rec.result.status == "Maximum_Iterations_Exceeded"
    cand = ctrl.fhocp.reference.evaluate(x, np.tile(ref.u_bar, (N, 1)), ref.x_bar, ref.u_bar,
                                   0.02, ref.alpha)
    if rec.result.feasible:
        assert rec.suboptimal and not rec.fallback
        np.testing.assert_array_equal(rec.u, rec.result.u[0])
        assert rec.result.cost <= cand.cost or not (cand.constraint_violation <= FEAS_TOL
                                                    and cand.terminal_violation <= FEAS_TOL)
    else:
        assert rec.fallback and not rec.suboptimal
    s = ctrl.summary()
    assert s["suboptimal_steps"] + s["fallbacks"] == 1


@pytest.fixture(scope="module")
def sqp(cert):
    return make(cert, solver="sqp", sqp_options={"max_iter": 100})  # cold starts too


@pytest.mark.parametrize("y0, y_bar", [((0.0, 0.0), (0.1, 0.1)),
                                       ((0.15, -0.1), (0.0, 0.05))])
def test_sqp_option_agrees_with_ipopt_and_passes_checks(model, cert, fast, reference, sqp,
                                                        y0, y_bar):
    """``solver="sqp"`` (casadi sqpmethod + qpOASES on the same callbacks) reaches IPOPT's
    optimum, and its answer passes the same independent residual checks."""
    x_hat = start_state(model, np.array(y0))
    ref = cert.reference(np.array(y_bar))
    fast.reset_warm_start()
    sqp.reset_warm_start()
    a = fast.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    b = sqp.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, u_init=a.u, warm=False)
    c = sqp.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert a.success and b.success and c.success, (a.status, b.status, c.status)
    assert b.cost == pytest.approx(a.cost, rel=1e-6, abs=1e-9)
    tight = reference.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, u_init=c.u,
                            warm=False)
    assert tight.success and c.cost == pytest.approx(tight.cost, rel=1e-6, abs=1e-9)
    x, _ = simulate(model.params, x_hat, c.u)
    np.testing.assert_allclose(x, c.x, atol=1e-12)
    assert c.constraint_violation <= FEAS_TOL and c.terminal_violation <= FEAS_TOL
    assert c.defect <= 1e-8 and c.status == "optimal"


def test_sqp_closed_loop_warm_start_and_rejects_wrong_answers(model, cert):
    """Closed loop with the SQP option: warm-started solves succeed in few iterations; a
    solver answer that violates the terminal set is rejected by the residual checks."""
    fh = make(cert, solver="sqp")
    ctrl = PaperMPC(fh)
    ref = cert.reference(np.array([0.1, 0.1]))
    ctrl.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    x = start_state(model, np.array([0.0, 0.05]))
    for _ in range(N):
        rec = ctrl.make_step(x, 0.02)
        assert rec.result.success and not rec.fallback, rec.result.status
        x = step(model.params, x, rec.u)
    assert rec.result.iterations <= 3
    buf, real, ins, outs = fh._buffer

    def lying() -> None:
        real()
        outs["x"][:] = 1.0

    fh._buffer = (buf, lying, ins, outs)
    res = fh.solve(x, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
    assert not res.success and res.terminal_violation > 0


@pytest.mark.parametrize("loop", ["kernel", "casadi"])
def test_sqp_time_budget_stops_the_solve(model, cert, loop):
    fh = make(cert, solver="sqp", time_budget=0.0, sqp_options={"loop": loop})
    ref = cert.reference(np.array([0.1, 0.1]))
    res = fh.solve(start_state(model, np.array([0.0, 0.05])), 0.02, ref.x_bar, ref.u_bar,
                   ref.alpha, warm=False)
    assert res.status == "time_budget_exceeded" and not res.success


def test_default_solver_is_sqp_unless_ipopt_options_given(cert):
    data = FHOCPData(cert.params, cert.N, cert.Q, cert.R, cert.L, cert.h, cert.w_L, cert.a,
                     cert.b, cert.s)
    assert FHOCP(data, reference=FixedSetpoint()).solver == "sqp"
    assert FHOCP(data, reference=FixedSetpoint(), ipopt_options={"max_iter": 100}).solver == "ipopt"
    assert FHOCP(data, reference=FixedSetpoint(), formulation="multiple-shooting").solver == "ipopt"
    # a certificate is such data
    assert FHOCP(cert, reference=FixedSetpoint()).N == FHOCP(
        data, reference=FixedSetpoint()).N == cert.N


def test_sqp_solver_rejected_for_multiple_shooting(cert):
    with pytest.raises(ValueError, match="solver"):
        make(cert, formulation="multiple-shooting", solver="sqp")


class CountingReference(FixedSetpoint):
    """A third law's reference (the :class:`~controllers.ocp.reference.Reference` protocol):
    the paper's set-point, with the calls the FHOCP's one solve procedure makes counted."""

    name = "counting"

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[str] = []

    def fallback(self, x_hat, e_o, request, status):
        self.calls.append("fallback")
        return super().fallback(x_hat, e_o, request, status)

    def write(self, ins, x_hat, e_o, request):
        self.calls.append("write")
        super().write(ins, x_hat, e_o, request)

    def check_answer(self, wopt, pv, x_hat, e_o, request, status):
        self.calls.append("check_answer")
        return super().check_answer(wopt, pv, x_hat, e_o, request, status)


def test_one_fhocp_takes_any_reference(model, cert):
    """The FHOCP with another reference object goes through the same procedure and gives the
    default's answer to the bit: the i = 0 row first (the reference's fallback, no solver),
    else write, solve, the reference's answer check, the one judge."""
    fh = FHOCP.from_certificate(cert, reference=FixedSetpoint()).setup()
    x_hat = start_state(model, np.array([0.05, 0.0]))
    ref = cert.reference(np.array([0.1, 0.1]))
    plain = fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    reference = CountingReference()
    counted = FHOCP.from_certificate(cert, reference=reference).setup()
    again = counted.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha, warm=False)
    assert reference.calls == ["write", "check_answer"] and counted.reference is reference
    assert again.success and again.status == plain.status == "optimal"
    assert np.array_equal(again.u, plain.u) and again.cost == plain.cost
    reference.calls.clear()
    refused = counted.solve(x_hat, 1.0, ref.x_bar, ref.u_bar, ref.alpha)   # a_0 ê_o > range
    assert reference.calls == ["fallback"] and refused.status == "infeasible_x0"
    assert not refused.success and np.array_equal(refused.u, np.tile(ref.u_bar, (fh.N, 1)))


def test_a_reference_object_serves_one_fhocp_and_its_formulations(cert):
    """A reference keeps its FHOCP's layout: a second FHOCP refuses it; the tracking law's is
    single shooting only, refused by name for multiple shooting."""
    from controllers.errors import DesignError
    from controllers.laws.tracking.reference import ArtificialSteadyState

    reference = FixedSetpoint()
    FHOCP.from_certificate(cert, reference=reference)
    with pytest.raises(DesignError, match="already serves another FHOCP"):
        FHOCP.from_certificate(cert, reference=reference)
    with pytest.raises(DesignError, match="tracking law's FHOCP is single-shooting only"):
        FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1e3, 0.05),
                               formulation="multiple-shooting")
