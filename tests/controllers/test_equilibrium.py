"""Model equilibria (controllers.equilibrium): residuals, box, closed form, unreachable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.equilibrium import (
    UnreachableSetpoint,
    equilibrium,
    equilibrium_for_output,
    jacobians,
    state_equilibrium,
)
from controllers.errors import ControllersError
from controllers.gru import output, step
from tests.controllers.random_gru import random_gru_model


def test_jacobians_match_finite_differences() -> None:
    rng = np.random.default_rng(0)
    p = random_gru_model(0, n=7).params
    for _ in range(5):
        x, u = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 2)
        fx, fu = jacobians(p, x, u)
        eps = 1e-6
        fd_x = np.array([(step(p, x + eps * e, u) - step(p, x - eps * e, u)) / (2 * eps)
                         for e in np.eye(7)]).T
        fd_u = np.array([(step(p, x, u + eps * e) - step(p, x, u - eps * e)) / (2 * eps)
                         for e in np.eye(2)]).T
        assert fx == pytest.approx(fd_x, abs=1e-8)
        assert fu == pytest.approx(fd_u, abs=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_equilibrium_residuals_are_tiny(seed: int) -> None:
    m = random_gru_model(seed)
    p = m.params
    # set-points generated from inputs inside the box are reachable by construction
    for u_true in np.random.default_rng(seed).uniform(-0.9, 0.9, (4, 2)):
        y_bar = output(p, state_equilibrium(p, u_true))
        x, u = equilibrium(m, y_bar)
        assert np.max(np.abs(step(p, x, u) - x)) < 1e-12
        assert np.max(np.abs(output(p, x) - y_bar)) < 1e-9
        assert np.max(np.abs(u)) <= 1.0 and np.max(np.abs(x)) < 1.0
        assert u == pytest.approx(u_true, abs=1e-6)  # the map u → ȳ is injective here


def test_closed_form_scalar_model() -> None:
    """n = m = p = 1 with U_z = U_r = U_h = 0: x̄ = tanh(W_h ū + b_h), ȳ = U_o x̄ + b_o."""
    p = {"W_z": np.array([[0.3]]), "U_z": np.zeros((1, 1)), "b_z": np.array([2.0]),
         "W_r": np.array([[0.1]]), "U_r": np.zeros((1, 1)), "b_r": np.array([0.0]),
         "W_h": np.array([[0.8]]), "U_h": np.zeros((1, 1)), "b_h": np.array([0.1]),
         "U_o": np.array([[1.5]]), "b_o": np.array([0.2])}
    y_bar = 0.9
    x_hand = (0.9 - 0.2) / 1.5                       # 0.4667
    u_hand = (math.atanh(x_hand) - 0.1) / 0.8        # 0.5827
    x, u = equilibrium(p, [y_bar])
    assert x[0] == pytest.approx(x_hand, abs=1e-12)
    assert u[0] == pytest.approx(u_hand, abs=1e-10)
    # ȳ = 1.5 needs tanh(0.8 u + 0.1) = 0.8667, u = 1.54 > 1: not reachable
    with pytest.raises(UnreachableSetpoint, match="closest reachable"):
        equilibrium(p, [1.5])
    x_best, u_best = equilibrium_for_output(p, [1.5])
    assert u_best[0] == pytest.approx(1.0)  # saturated input gives the closest output
    assert output(p, x_best)[0] == pytest.approx(0.2 + 1.5 * math.tanh(0.9), abs=1e-10)


def test_unreachable_setpoint_message_in_physical_units() -> None:
    m = random_gru_model(0)
    y_far = m.normalize_y(np.array([5.0, 1.0]))
    with pytest.raises(ControllersError) as info:
        equilibrium(m, y_far)
    msg = str(info.value)
    assert "h1=5 m, h2=1 m" in msg and "not reachable" in msg and "\n" not in msg
    # the closest reachable output named in the message is what equilibrium_for_output gives
    x, _ = equilibrium_for_output(m, y_far)
    reach = m.denormalize_y(output(m.params, x))
    assert f"h1={reach[0]:.4g} m" in msg


def test_deterministic() -> None:
    m = random_gru_model(3)
    y = output(m.params, state_equilibrium(m.params, np.array([0.2, -0.4])))
    a = equilibrium(m, y)
    b = equilibrium(m, y)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


# -- any numbers of inputs and outputs ---------------------------------------------------------
@pytest.mark.parametrize(("m", "p"), [(1, 1), (3, 2), (2, 3), (1, 2)])
def test_equilibria_of_non_square_models(m: int, p: int) -> None:
    """A reachable output (from an input inside the box) is found by the least squares and
    by the Newton continuation (least-squares steps when m ≠ p); equilibrium_for_output
    (the GRU plant's and the observer's start) returns an equilibrium in every case."""
    from controllers.equilibrium import EQ_TOL, equilibrium_newton, equilibrium_output

    model = random_gru_model(5, n=8, m=m, p=p)
    x0, _ = equilibrium_output(model.params, np.zeros(m))
    for u_true in np.random.default_rng(m + 3 * p).uniform(-0.6, 0.6, (3, m)):
        _, y = equilibrium_output(model.params, u_true, x0)
        x, u = equilibrium(model, y)
        assert np.max(np.abs(step(model.params, x, u) - x)) < 1e-12
        assert np.max(np.abs(output(model.params, x) - y)) < 1e-9 and np.max(np.abs(u)) <= 1
        if m <= p:   # injective: the input itself
            assert u == pytest.approx(u_true, abs=1e-6)
        eq = equilibrium_newton(model.params, y, x0, np.zeros(m))
        assert eq is not None
        assert np.max(np.abs(output(model.params, eq[0]) - y)) < EQ_TOL
        assert np.max(np.abs(step(model.params, *eq) - eq[0])) < EQ_TOL
        xs, us = equilibrium_for_output(model, y + 0.3)
        assert np.max(np.abs(step(model.params, xs, us) - xs)) < 1e-12
        assert np.max(np.abs(us)) <= 1


def test_more_outputs_than_inputs_names_the_closest_reachable_output() -> None:
    """p = 2 outputs, m = 1 input: the equilibrium outputs form a curve; a set-point off it is
    unreachable (one line naming why and the closest reachable output), and the Newton
    continuation gives no equilibrium for it either."""
    from controllers.equilibrium import equilibrium_newton, equilibrium_output

    model = random_gru_model(2, n=8, m=1, p=2)
    x0, y0 = equilibrium_output(model.params, np.zeros(1))
    _, y1 = equilibrium_output(model.params, np.array([0.4]), x0)
    normal = np.array([-(y1 - y0)[1], (y1 - y0)[0]]) / np.linalg.norm(y1 - y0)
    off = 0.5 * (y0 + y1) + 0.05 * normal
    with pytest.raises(UnreachableSetpoint) as info:
        equilibrium(model, off)
    msg = str(info.value)
    assert "\n" not in msg and "not reachable" in msg
    assert "(2 outputs, 1 input: only the model's 1-dimensional surface of equilibrium " \
           "outputs is reachable)" in msg
    xb, _ = equilibrium_for_output(model, off)
    reach = model.denormalize_y(output(model.params, xb))
    assert msg.endswith(f"closest reachable equilibrium output is h1={reach[0]:.4g} m, "
                        f"h2={reach[1]:.4g} m")
    assert np.linalg.norm(output(model.params, xb) - off) <= 0.05 + 1e-9
    assert equilibrium_newton(model.params, off, x0, np.zeros(1)) is None


@pytest.mark.parametrize(("m", "p"), [(1, 1), (1, 2), (2, 2), (3, 2), (3, 1), (2, 3)])
def test_reachable_boundary_of_an_m_dimensional_input_box(m: int, p: int) -> None:
    """The edge of the reachable set-points: the outputs along u ∈ [−1, 1] (m = 1), the square's
    edges as a closed path (m = 2), and for m ≥ 3 with two outputs the outline of the faces'
    outputs, which holds the outputs of inputs drawn inside the box."""
    from matplotlib.path import Path as Polygon

    from controllers.equilibrium import box_boundary, equilibrium_output, reachable_boundary

    model = random_gru_model(1, n=8, m=m, p=p)
    edge = reachable_boundary(model, points=30)
    assert edge.ndim == 2 and edge.shape[1] == p and np.all(np.isfinite(edge))
    inputs = box_boundary(m, 30)
    assert np.all(np.max(np.abs(inputs), axis=1) == 1.0) or m == 1
    if m == 1:
        expect = [model.denormalize_y(equilibrium_output(model.params, u)[1]) for u in inputs]
        np.testing.assert_allclose(edge, expect, atol=1e-12)
        assert edge.shape[0] == 30
    if m == 2 or (m >= 3 and p == 2):
        np.testing.assert_allclose(edge[0], edge[-1], atol=1e-10)   # closed
    if m >= 3 and p != 2:
        assert edge.shape[0] == inputs.shape[0] == m * 2 ** (m - 1) * 30   # the edges
    inside = np.random.default_rng(0).uniform(-0.9, 0.9, (40, m))
    ys = np.array([model.denormalize_y(equilibrium_output(model.params, u)[1])
                   for u in inside])
    if p == 2 and m >= 2:
        assert Polygon(edge).contains_points(ys).all()
    if p == 1:   # the reachable interval
        assert np.all((ys >= edge.min() - 1e-12) & (ys <= edge.max() + 1e-12))
