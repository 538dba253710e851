"""Certificates of the paper (controllers.certification.certificates) against hand-computed values.

The hand model below has n = 2, m = 1, p = 1 and weights chosen so that every norm can be
read off by eye; the expected values were computed by hand (the arithmetic is written next to
each literal) independently of the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog, minimize

from controllers import problem
from controllers.certification import bounds, gain_design
from controllers.certification import certificates as certs
from controllers.errors import ControllersError
from controllers.gru import output, step
from controllers.model import GRUModel
from controllers.problem import Channel, ControlProblem
from tests.controllers.random_gru import random_gru_model


def hand_model(w_y_bar: float | None = 0.05) -> GRUModel:
    """n = 2, m = 1, p = 1; output h1 with offset 1, scale 1 (so [0, 2] m → [−1, 1])."""
    params = {
        # rows of [W_z U_z b_z]: 0.55 + 0.05 + 2 = 2.6 ; 0 + 0.05 + 1 = 1.05  → 2.6
        "W_z": np.array([[0.55], [0.0]]), "U_z": np.array([[0.05, 0.0], [0.0, -0.05]]),
        "b_z": np.array([2.0, 1.0]),
        # rows of [W_r U_r b_r]: 0.2 + 0.4 + 0 = 0.6 ; 0.1 + 0.2 + 0.5 = 0.8  → 0.8
        "W_r": np.array([[0.2], [0.1]]), "U_r": np.array([[0.3, -0.1], [0.0, 0.2]]),
        "b_r": np.array([0.0, 0.5]),
        # rows of [W_h U_h b_h]: 1 + 0.3 + 0 = 1.3 ; 0.5 + 0.4 + 0.1 = 1.0  → 1.3
        "W_h": np.array([[1.0], [0.5]]), "U_h": np.array([[0.2, 0.1], [-0.1, 0.3]]),
        "b_h": np.array([0.0, 0.1]),
        "U_o": np.array([[1.0, 2.0]]), "b_o": np.array([0.0]),
    }
    problem = ControlProblem(name="siso", Ts=25.0,
                             inputs=(Channel("qa", "m3/s", 0.0, 9.05e-4),),
                             outputs=(Channel("h1", "m", 0.0, 2.0),))
    return GRUModel(params=params, u_offset=np.array([4.525e-4]), u_scale=np.array([4.525e-4]),
                    y_offset=np.array([1.0]), y_scale=np.array([1.0]), input_names=["qa"],
                    input_units=["m3/s"], output_names=["h1"], output_units=["m"], Ts=25.0,
                    w_y_bar=w_y_bar, problem=problem)


# σ̄_z = σ(2.6), σ̄_r = σ(0.8), φ̄_h = tanh(1.3)
SZ, SR, PH = 0.9308615796566533, 0.6899744811276125, 0.8617231593133063
# ν = ‖U_h‖(¼‖U_r‖ + σ̄_r) + ¼(1 + φ̄_h)/(1 − σ̄_z)‖U_z‖ = 0.4(0.1 + σ̄_r) + ¼·1.8617/0.0691·0.05
NU = 0.6525832433260879
RHO_S = 0.9759801542427569          # σ̄_z + (1 − σ̄_z) ν
# LP gains: row i of U − l U_o, U_o = [1 2]: min_l |U_i1 − l| + |U_i2 − 2 l| (weighted median)
#   U_z rows (0.05, 0) → l = 0 (value 0.05);  (0, −0.05) → l = −0.025 (value 0.025)
#   U_r rows (0.3, −0.1) → l = −0.05 (value 0.35); (0, 0.2) → l = 0.1 (value 0.1)
LZ = np.array([[0.0], [-0.025]])
LR = np.array([[-0.05], [0.1]])
NU_O = 0.6475832433260877           # ν with ‖U_r − L_r U_o‖ = 0.35 and ‖U_z − L_z U_o‖ = 0.05
RHO_O = 0.9756344621410401
KAPPA = 0.0209443855422747          # ¼(1 + φ̄_h)·0.025 + ¼ σ̄_z·0.4·0.1
L_MAX = 0.0628331566268241          # ¼(1 + φ̄_h)·0.075 + ¼ σ̄_z·0.4·0.3
W_BAR = 0.001047219277113735        # κ · 0.05
# N = 2, c_s = c_o = [3, 3] (|1| + |2| for L = [1; −1]):
A1 = 3.115402856303593              # ρ_o·3 + ρ_s^0 L_max·3
A2 = 3.2234661317510374             # ρ_o a_1 + ρ_s L_max·3
B1 = 0.00628331566268241            # 0 + a_0 w̄ + 3 w̄
B2 = 0.012612021284589077           # b_1 + a_1 w̄ + 3 ρ_s w̄
E_INF = 0.042979526377606436        # w̄ / (1 − ρ_o)  (> ê_o,0 = 0.02, so ẽ_o = ē_∞)
S = 84.27663730261547               # n λ_max(Q)/(1 − ρ_s²) with n = 2, Q = diag(1, 2)
ALPHA_01 = 0.23294831035949873      # ȳ = 0.1: (1 − 0.1 − ẽ_o a_2 − b_2 − 0.05)/3
ALPHA_MIN = 0.14862209107529        # ρ_s²(L_max ẽ_o + w̄)/(1 − ρ_s)


@pytest.fixture(scope="module")
def hand_cert() -> certs.Certificate:
    return certs.compute_certificate(hand_model(), N=2, Q=np.diag([1.0, 2.0]), e_o0=0.02)


def test_gate_bounds_nu_rho_s_hand(hand_cert: certs.Certificate) -> None:
    assert bounds.gate_bounds(hand_model().params) == pytest.approx((SZ, SR, PH), rel=1e-12)
    assert hand_cert.sigma_z == pytest.approx(SZ, rel=1e-12)
    assert hand_cert.nu == pytest.approx(NU, rel=1e-12)
    assert hand_cert.rho_s == pytest.approx(RHO_S, rel=1e-12)
    assert bounds.rho_s(hand_model().params) == pytest.approx(RHO_S, rel=1e-12)
    assert hand_cert.c_s == pytest.approx([3.0, 3.0])
    assert pytest.approx(np.array([[1.0], [-1.0]])) == hand_cert.L
    assert hand_cert.h == pytest.approx([1.0, 1.0])


def test_lp_gains_and_observer_quantities_hand(hand_cert: certs.Certificate) -> None:
    assert hand_cert.L_z == pytest.approx(LZ, abs=1e-9)
    assert hand_cert.L_r == pytest.approx(LR, abs=1e-9)
    assert hand_cert.gain_scale == 1.0
    assert hand_cert.nu_o == pytest.approx(NU_O, rel=1e-9)
    assert hand_cert.rho_o == pytest.approx(RHO_O, rel=1e-9)
    assert hand_cert.kappa == pytest.approx(KAPPA, rel=1e-9)
    assert hand_cert.L_max == pytest.approx(L_MAX, rel=1e-9)
    assert hand_cert.c_o == pytest.approx([3.0, 3.0])
    assert hand_cert.w_y_bar == 0.05
    assert hand_cert.w_bar == pytest.approx(W_BAR, rel=1e-9)
    assert hand_cert.w_L == pytest.approx([0.05, 0.05])


def test_tightening_terminal_and_setpoint_checks_hand(hand_cert: certs.Certificate) -> None:
    c = hand_cert
    assert c.a.shape == (3, 2) and c.b.shape == (3, 2)
    assert c.a[:, 0] == pytest.approx([3.0, A1, A2], rel=1e-9)
    assert c.b[:, 0] == pytest.approx([0.0, B1, B2], rel=1e-9)
    assert c.a[:, 1] == pytest.approx(c.a[:, 0]) and c.b[:, 1] == pytest.approx(c.b[:, 0])
    assert c.e_inf == pytest.approx(E_INF, rel=1e-9)
    assert c.e_tilde == pytest.approx(E_INF, rel=1e-9)
    assert c.s == pytest.approx(S, rel=1e-9)
    assert c.alpha([0.1]) == pytest.approx(ALPHA_01, rel=1e-9)
    assert c.alpha_min() == pytest.approx(ALPHA_MIN, rel=1e-9)
    assert c.assumption_1([0.1]) and c.recursive_feasibility([0.1]) and c.ok([0.1])
    # ȳ = 0.5: α = (0.79885 − 0.5)/3 ≈ 0.0996 ∈ (0, α_min): Assumption 1 holds, eq. 11 fails
    assert c.alpha([0.5]) == pytest.approx(ALPHA_01 - 0.4 / 3, rel=1e-9)
    assert c.assumption_1([0.5]) and not c.recursive_feasibility([0.5])
    f = c.failures([0.5])
    assert len(f) == 1 and "eq:condition-recursive-feasibility" in f[0]
    # ȳ = 0.9: α < 0, both fail, each named
    assert c.alpha([0.9]) < 0 and not c.assumption_1([0.9])
    text = " | ".join(c.failures([0.9]))
    assert "Assumption 1" in text and "alpha" in text and "recursive feasibility" in text
    # tightened bounds for the FHOCP: h − a_i ê_o − b_i − w_L
    tb = c.tightened_bounds(0.02)
    assert tb[:, 0] == pytest.approx(1.0 - np.array([3.0, A1, A2]) * 0.02
                                     - np.array([0.0, B1, B2]) - 0.05, rel=1e-9)


def test_eo_evolution_monotone_to_e_inf(hand_cert: certs.Certificate) -> None:
    e = hand_cert.e_o(2000)
    assert e[0] == 0.02
    assert np.all(np.diff(e) >= 0) and np.all(np.diff(e[:100]) > 0)  # ê_o,0 < ē_∞: rising
    assert e[-1] == pytest.approx(E_INF, rel=1e-9)
    e2 = hand_cert.e_o(2000, e_o0=0.5)
    assert np.all(np.diff(e2) <= 0) and np.all(np.diff(e2[:100]) < 0)
    assert e2[-1] == pytest.approx(E_INF, rel=1e-9)
    assert e[1] == pytest.approx(RHO_O * 0.02 + W_BAR, rel=1e-12)


def test_inf_norm_of_a_row_is_the_sum_of_absolute_values() -> None:
    assert bounds.inf_norm([1.0, -2.0, 0.5]) == 3.5
    assert bounds.inf_norm([[1.0, -2.0], [0.5, 0.5]]) == 3.0
    assert bounds.row_norms([[1.0, -2.0], [0.5, 0.5]]) == pytest.approx([3.0, 1.0])


def test_output_constraints_in_normalised_units() -> None:
    m = random_gru_model(0)
    m.y_offset = np.array([1.0, 0.5])
    m.y_scale = np.array([0.5, 2.0])
    L, h = problem.output_constraints(m)
    assert pytest.approx(np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=float)) == L
    # h1 ∈ [0, 2]: (2 − 1)/0.5 = 2, −(0 − 1)/0.5 = 2 ; h2: (2 − 0.5)/2 = 0.75, −(0 − 0.5)/2
    assert h == pytest.approx([2.0, 2.0, 0.75, 0.25])
    # the polytope maps back to the physical box
    for y_phys, inside in (([0.1, 1.9], True), ([2.01, 1.0], False), ([1.0, -0.01], False)):
        assert bool(np.all(L @ m.normalize_y(np.array(y_phys)) <= h)) is inside


def test_to_json_has_exactly_the_paper_keys(hand_cert: certs.Certificate) -> None:
    import json

    doc = hand_cert.to_json([0.1])
    assert list(doc) == list(certs.JSON_KEYS)
    assert set(doc) == {"sigma_z", "sigma_r", "phi_h", "nu", "rho_s", "c_s", "L_z", "L_r",
                        "nu_o", "rho_o", "c_o", "kappa", "L_max", "w_y_bar", "w_bar", "w_L",
                        "a", "b", "e_o0", "e_inf", "s", "s_measured", "alpha", "assumption_1",
                        "recursive_feasibility"}
    json.dumps(doc)  # serialisable
    assert doc["alpha"] == pytest.approx(ALPHA_01) and doc["assumption_1"] is True
    assert np.array(doc["a"]).shape == (3, 2) and np.array(doc["L_z"]).shape == (2, 1)
    none = hand_cert.to_json()
    assert none["alpha"] is None and none["recursive_feasibility"] is None


def test_failures_name_the_delta_iss_and_observer_conditions() -> None:
    m = hand_model()
    m.params["U_z"] = m.params["U_z"] * 10  # ‖U_z‖ = 0.5 → ν ≈ 3.6
    c = certs.compute_certificate(m, N=2)
    assert c.nu > 1
    f = c.failures([0.0])
    assert any("th:stability-bonassi" in s and "nu =" in s for s in f)
    assert any("eq:condition-observer-convergence" in s for s in f)
    assert not c.ok() and not c.ok([0.0])


def test_explicit_gains_scale_and_missing_w_y_bar() -> None:
    m = hand_model()
    c = certs.compute_certificate(m, N=2, gain_scale=0.5)
    assert c.L_z == pytest.approx(0.5 * LZ, abs=1e-9) and c.gain_scale == 0.5
    c0 = certs.compute_certificate(m, N=2, L_z=np.zeros((2, 1)), L_r=np.zeros((2, 1)))
    # rem:observer-gains: open-loop observer ⇒ ν_o = ν, κ = L_max = w̄ = 0
    assert c0.nu_o == pytest.approx(NU) and c0.kappa == 0 and c0.L_max == 0 and c0.w_bar == 0
    m.L_z, m.L_r = 0.1 * LZ, 0.1 * LR  # saved gains are the default
    assert certs.compute_certificate(m, N=2).L_r == pytest.approx(0.1 * LR)
    with pytest.raises(ControllersError, match="w_y_bar"):
        certs.compute_certificate(hand_model(w_y_bar=None), N=15)
    with pytest.raises(ControllersError, match="shape"):
        certs.compute_certificate(m, N=15, L_z=np.zeros((3, 1)), L_r=np.zeros((3, 1)))


def test_lp_gains_are_optimal() -> None:
    """Each row of the LP gains minimises ‖U_i − l U_o‖₁: LP duality and local search."""
    rng = np.random.default_rng(3)
    for seed in range(3):
        p = random_gru_model(seed, n=6).params
        Lz, Lr = gain_design.observer_gains_lp(p)
        Uo = p["U_o"]
        for U, Lg in ((p["U_z"], Lz), (p["U_r"], Lr)):
            for i in range(U.shape[0]):
                c, A = U[i], Uo.T
                val = np.abs(c - A @ Lg[i]).sum()
                # dual: max yᵀc s.t. Aᵀy = 0, −1 ≤ y ≤ 1 has the same optimum
                dual = linprog(-c, A_eq=A.T, b_eq=np.zeros(A.shape[1]),
                               bounds=[(-1, 1)] * len(c), method="highs")
                assert -dual.fun == pytest.approx(val, abs=1e-9)
                # no random perturbation improves it
                for _ in range(50):
                    d = Lg[i] + rng.normal(0, 1e-3, Lg[i].shape)
                    assert np.abs(c - A @ d).sum() >= val - 1e-12
                # nor does a derivative-free search from zero
                res = minimize(lambda v, c=c, A=A: np.abs(c - A @ v).sum(), np.zeros(2),
                               method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12})
                assert res.fun >= val - 1e-9
        # and the ∞-norm, hence ν_o, is no larger than with zero gains or any other tried
        assert bounds.nu_o(p, Lz, Lr) <= bounds.nu(p) + 1e-12
        for _ in range(20):
            assert bounds.nu_o(p, Lz + rng.normal(0, 0.01, Lz.shape),
                          Lr + rng.normal(0, 0.01, Lr.shape)) >= bounds.nu_o(p, Lz, Lr) - 1e-12


def test_lp_gains_brute_force_grid_p1() -> None:
    m = hand_model()
    Lz, Lr = gain_design.observer_gains_lp(m.params)
    grid = np.linspace(-0.5, 0.5, 20001)
    Uo = m.params["U_o"][0]
    for U, Lg in ((m.params["U_z"], Lz), (m.params["U_r"], Lr)):
        for i in range(2):
            vals = np.abs(U[i][None, :] - grid[:, None] * Uo[None, :]).sum(axis=1)
            assert np.abs(U[i] - Lg[i, 0] * Uo).sum() <= vals.min() + 1e-12
            assert Lg[i, 0] == pytest.approx(grid[np.argmin(vals)], abs=1e-4)


def test_lem_vs_contraction_and_constraint_gain() -> None:
    """eq:incremental-lyap-neg-def and eq:incremental-lyap-constraints on random pairs."""
    rng = np.random.default_rng(7)
    for seed in range(3):
        m = random_gru_model(seed, n=8)
        p = m.params
        c = certs.compute_certificate(m, N=15, w_y_bar=0.01)
        assert c.nu < 1
        worst = 0.0
        for _ in range(2000):
            xa, xb = rng.uniform(-1, 1, (2, 8))
            if rng.random() < 0.5:
                xb = xa + rng.normal(0, 1e-3, 8).clip(-1 - xa, 1 - xa)
            u = rng.uniform(-1, 1, 2)
            d = np.max(np.abs(xa - xb))
            dplus = np.max(np.abs(step(p, xa, u) - step(p, xb, u)))
            assert dplus <= c.rho_s * d + 1e-15
            assert np.all(c.L @ p["U_o"] @ (xa - xb) <= c.c_s * d + 1e-12)
            worst = max(worst, dplus / d)
        assert 0 < worst < c.rho_s


def test_choose_gain_scale_returns_the_largest_passing_scale() -> None:
    m = random_gru_model(1)
    m.w_y_bar = 0.02  # small model error: the LP gains themselves pass
    setpoints = [m.normalize_y(np.array(s)) for s in ((0.5, 0.5), (1.0, 1.4), (1.5, 1.5))]
    assert gain_design.choose_gain_scale(m, setpoints, N=15)[0] == 1.0
    m.w_y_bar = 0.15  # larger error: the LP gains fail, a smaller scale passes (≈ 0.42)
    theta, c = gain_design.choose_gain_scale(m, setpoints, N=15)
    assert theta is not None and 0.1 < theta < 1
    assert not certs.compute_certificate(m, N=15).ok(setpoints[0])
    assert c.gain_scale == theta and all(c.ok(y) for y in setpoints)
    Lz, Lr = gain_design.observer_gains_lp(m.params)
    assert c.L_z == pytest.approx(theta * Lz)
    # slightly larger gains fail somewhere (eq. 11 is the binding condition here)
    c2 = certs.compute_certificate(m, N=15, L_z=1.001 * theta * Lz, L_r=1.001 * theta * Lr)
    assert not all(c2.ok(y) for y in setpoints)
    # an impossible set-point (on the constraint) fails even with θ = 0
    theta_bad, c_bad = gain_design.choose_gain_scale(m, [m.normalize_y(np.array([2.0, 1.0]))], N=15)
    assert theta_bad is None and c_bad.gain_scale == 0.0


def test_alpha_positive_iff_assumption_1() -> None:
    m = random_gru_model(4)
    m.w_y_bar = 0.05
    c = certs.compute_certificate(m, N=15)
    for y in np.random.default_rng(1).uniform(-1, 1, (200, 2)):
        assert (c.alpha(y) > 0) == c.assumption_1(y)
        assert math.isfinite(c.alpha(y))


def test_ok_is_exactly_no_failures() -> None:
    """ok() (the governor's fast test) agrees with failures() on admissible and inadmissible
    set-points alike."""
    m = random_gru_model(4)
    m.w_y_bar = 0.05
    c = certs.compute_certificate(m, N=15)
    verdicts = set()
    for y in np.random.default_rng(2).uniform(-1.5, 1.5, (300, 2)):
        assert c.ok(y) == (not c.failures(y))
        verdicts.add(c.ok(y))
    assert verdicts == {True, False} and c.ok() == (not c.failures())


def test_reference_gives_equilibrium_and_alpha_or_a_clear_error() -> None:
    from controllers.gru import output

    m = random_gru_model(1)
    m.w_y_bar = 0.02
    c = certs.compute_certificate(m, N=15)
    y = m.normalize_y(np.array([1.0, 1.1]))
    ref = c.reference(y)
    assert ref.alpha == pytest.approx(c.alpha(y))
    assert output(m.params, ref.x_bar) == pytest.approx(y, abs=1e-9)
    assert np.max(np.abs(step(m.params, ref.x_bar, ref.u_bar) - ref.x_bar)) < 1e-12
    # on the constraint: Assumption 1 fails, named with the set-point in metres
    with pytest.raises(ControllersError, match=r"set-point h1=2 m, h2=1 m: .*Assumption 1"):
        c.reference(m.normalize_y(np.array([2.0, 1.0])))
    # admissible for the certificate but not reachable by the model
    with pytest.raises(ControllersError, match="not reachable"):
        c.reference(m.normalize_y(np.array([0.5, 1.5])))


def test_tightening_recursion_identity(hand_cert: certs.Certificate) -> None:
    """The step of the recursive-feasibility proof: for every i and ê_o,
    h − a_{i+1} ê − b_{i+1} + c_s ρ_s^i (L_max ê + w̄) = h − a_i (ρ_o ê + w̄) − b_i."""
    rng = np.random.default_rng(0)
    for c in (hand_cert, certs.compute_certificate(random_gru_model(2), N=15, w_y_bar=0.1)):
        for e in rng.uniform(0, 1, 5):
            for i in range(c.N):
                lhs = (-c.a[i + 1] * e - c.b[i + 1]
                       + c.c_s * c.rho_s**i * (c.L_max * e + c.w_bar))
                rhs = -c.a[i] * (c.rho_o * e + c.w_bar) - c.b[i]
                assert lhs == pytest.approx(rhs, rel=1e-12, abs=1e-14)


def test_candidate_solution_deviation_bound() -> None:
    """eq:bound-epsilon with the model as plant: the shifted candidate started at the new
    estimate stays within ρ_s^{i−1} (L_max ‖x − x̂‖ + κ‖w_y‖) of the previous prediction."""
    from controllers.observer import GRUObserver

    m = random_gru_model(3, n=10)
    p = m.params
    c = certs.compute_certificate(m, N=15, w_y_bar=0.2)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(200):
        x = rng.uniform(-1, 1, 10)
        x_hat = np.clip(x + rng.uniform(-0.3, 0.3, 10), -1, 1)
        e = np.max(np.abs(x - x_hat))
        u = rng.uniform(-1, 1, (c.N + 1, 2))  # u*_0..u*_{N-1}, then ū
        pred = [x_hat]
        for i in range(c.N + 1):
            pred.append(step(p, pred[-1], u[i]))      # x*_{0..N+1|k}
        w = rng.uniform(-0.2, 0.2, 2)
        obs = GRUObserver.from_certificate(c, x0=x_hat)
        cand = obs.make_step(u[0], output(p, x) + w)  # x̃_{0|k+1} = x̂_{k+1}
        bound0 = c.L_max * e + c.kappa * np.max(np.abs(w))
        for i in range(1, c.N + 2):
            dev = np.max(np.abs(cand - pred[i]))      # ‖ε_{k+i}‖
            assert dev <= c.rho_s ** (i - 1) * bound0 + 1e-13
            worst = max(worst, dev / (c.rho_s ** (i - 1) * bound0))
            if i <= c.N:
                cand = step(p, cand, u[i])
    assert 0 < worst <= 1


@pytest.mark.parametrize("kwargs, message", [
    ({"N": 2.5}, "horizon N must be an integer >= 1, got 2.5"),
    ({"N": True}, "horizon N must be an integer >= 1, got True"),
    ({"N": "abc"}, "horizon N must be an integer >= 1, got 'abc'"),
    ({"N": 0}, "horizon N must be >= 1 and <= 1000, got 0"),
    ({"N": 10**9}, "horizon N must be >= 1 and <= 1000, got 1000000000"),
    ({"e_o0": -1}, "e_o0 must be a non-negative number, got -1"),
    ({"e_o0": "x"}, "e_o0 must be a non-negative number, got 'x'"),
    ({"R": -1}, "cost weight R must be a 1x1 matrix, got shape ()"),
    ({"R": "abc"}, "cost weight R must be a 1x1 matrix of numbers, got 'abc'"),
    ({"R": [[-0.01]]}, "cost weight R must be symmetric positive definite"),
    ({"Q": [1, 2]}, "cost weight Q must be a 2x2 matrix, got shape (2,)"),
    ({"Q": [[1, 0.5], [0, 1]]}, "cost weight Q must be symmetric positive definite"),
    ({"Q": [[1, 0], [0, float("nan")]]}, "cost weight Q has non-finite entries"),
    ({"gain_scale": -1}, "gain scale must be a non-negative number, got -1"),
    ({"gain_scale": "x"}, "gain scale must be a non-negative number, got 'x'"),
])
def test_bad_design_parameters_are_one_line_errors(kwargs, message) -> None:
    with pytest.raises(ControllersError) as info:
        certs.compute_certificate(hand_model(), **{"N": 15, **kwargs})
    assert str(info.value) == message


def test_integer_valued_float_horizon_is_accepted() -> None:
    cert = certs.compute_certificate(hand_model(), N=3.0)
    assert cert.N == 3 and isinstance(cert.N, int) and len(cert.a) >= 3


def test_saturated_or_non_finite_update_gate_is_a_one_line_error() -> None:
    """σ̄_z rounds to 1 once ‖[W_z U_z b_z]‖∞ > ~36.7: ν would divide by zero."""
    m = hand_model()
    m.params["b_z"] = np.array([36.0, 1.0])  # σ(36.6) < 1 in floating point: still defined
    assert math.isfinite(bounds.nu(m.params))
    m.params["b_z"] = np.array([40.0, 1.0])  # ‖·‖∞ = 40.6: σ̄_z == 1.0
    assert bounds.gate_bounds(m.params)[0] == 1.0
    for call in (lambda: bounds.nu(m.params), lambda: certs.compute_certificate(m, N=15),
                 lambda: gain_design.choose_gain_scale(m, [np.zeros(1)], N=15)):
        with pytest.raises(ControllersError, match=r"^sigma_z \(σ̄_z = σ\(‖\[W_z U_z b_z\]‖∞\) = "
                                             r"σ\(40\.6\), th:stability-bonassi\) rounds to 1"):
            call()
    m.source = "m.json"
    with pytest.raises(ControllersError, match=r"^m\.json: sigma_z .* rounds to 1"):
        certs.compute_certificate(m, N=15)
    m.params["b_z"] = np.array([np.nan, 1.0])
    with pytest.raises(ControllersError, match=r"is undefined: ‖\[W_z U_z b_z\]‖∞ = nan, the "
                                         "weights are not finite"):
        bounds.nu(m.params)
