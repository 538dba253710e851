"""The plant FMU's Co-Simulation integrator against an independent scipy reference."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fmus.fourtank_reference import (
    H_START,
    PARAMETERS,
    Q_EQ,
    QA_MAX,
    QB_MAX,
    random_inputs,
    read_step_csv,
    rhs,
    simulate_reference,
    step_scenario,
)
from tests.fmus.fourtank_run import LEVELS, Plant, run_cs

TOL = 1e-6  # [m], the accuracy requirement


@pytest.mark.slow
def test_cs_matches_solve_ivp_over_20000_random_steps(fmu2_path, fmu3_path):
    u = random_inputs(20_000, seed=2024)
    # The sequence exercises the whole input range, including pumps-off holds.
    assert u[:, 0].max() > 0.95 * QA_MAX and u[:, 1].max() > 0.95 * QB_MAX
    assert np.all(u >= 0.0)
    y_ref = simulate_reference(u)
    y2 = run_cs(fmu2_path, u)
    err = np.abs(y2 - y_ref).max()
    assert err < TOL, f"FMI 2 CS deviates from solve_ivp by {err:.3g} m"
    # ... and the sequence really drained tanks to empty, where sqrt(h) is not Lipschitz.
    assert (y_ref == 0.0).any(axis=0).all()
    assert y2.min() >= 0.0
    # FMI 3 runs the same model and integrator: identical results.
    y3 = run_cs(fmu3_path, u)
    np.testing.assert_allclose(y3, y2, rtol=0, atol=1e-12)


def test_cs_matches_shipped_reference_csv(fmu2_path, fmu3_path):
    t, u, y_csv = read_step_csv()
    assert t[-1] == 25.0 * len(u)
    # The shipped file is what the reference produces today ...
    u_fresh, y_fresh = step_scenario()
    np.testing.assert_array_equal(u, u_fresh)
    np.testing.assert_allclose(y_csv, y_fresh, rtol=0, atol=1e-12)
    # ... and both FMUs reproduce it.
    for path in (fmu2_path, fmu3_path):
        y = run_cs(path, u)
        assert np.abs(y - y_csv).max() < TOL


def test_default_start_is_an_equilibrium(fmu2_path):
    u = np.tile(Q_EQ, (200, 1))
    y = run_cs(fmu2_path, u)
    np.testing.assert_allclose(y[0], H_START, rtol=0, atol=0)
    assert np.abs(y - np.array(H_START)).max() < 1e-9
    assert np.abs(rhs(H_START, *Q_EQ)).max() < 1e-12


def test_start_levels_are_settable_before_initialisation(fmu3_path):
    h0 = (0.2, 1.1, 0.0, 0.4)
    u = random_inputs(60, seed=5)
    y = run_cs(fmu3_path, u, **{f"h{i + 1}_start": h for i, h in enumerate(h0)})
    np.testing.assert_array_equal(y[0], h0)
    assert np.abs(y - simulate_reference(u, h0=h0)).max() < TOL


def test_empty_tank_stays_empty_without_going_negative(fmu2_path):
    plant = Plant(fmu2_path, "cs")
    try:
        plant.initialize()
        plant.set(qa=0.0, qb=0.0, qd3=-1e-5)  # pumps off and a leak in tank 3
        levels = []
        for _ in range(200):
            plant.do_step(25.0)
            levels.append(plant.get(*LEVELS))
        levels = np.array(levels)
        assert levels.min() >= 0.0
        np.testing.assert_array_equal(levels[-50:], 0.0)  # all drained, none below 0
        # A refill from empty works.
        plant.set(qa=QA_MAX, qd3=0.0)
        plant.do_step(25.0)
        h = plant.get(*LEVELS)
        assert h[0] > 0.0 and h[3] > 0.0
        assert plant.get("der(h1)")[0] > 0.0
    finally:
        plant.close()


def test_tunable_parameters_change_mid_run(fmu2_path, fmu3_path):
    """Halving outlet a1 after 40 steps matches the reference with the new parameter."""
    u = random_inputs(80, seed=11)
    first = simulate_reference(u[:40])
    changed = dict(PARAMETERS, a1=PARAMETERS["a1"] / 2, gamma_a=0.35)
    second = simulate_reference(u[40:], h0=first[-1], params=changed)
    expected = np.vstack([first, second[1:]])
    for path in (fmu2_path, fmu3_path):
        plant = Plant(path, "cs")
        try:
            plant.initialize()
            y = [plant.get(*LEVELS)]
            for k, (qa, qb) in enumerate(u):
                if k == 40:
                    plant.set(a1=changed["a1"], gamma_a=changed["gamma_a"])
                plant.set(qa=qa, qb=qb)
                plant.do_step(25.0)
                y.append(plant.get(*LEVELS))
        finally:
            plant.close()
        assert np.abs(np.array(y) - expected).max() < TOL
        # the change mattered
        assert np.abs(expected[-1] - simulate_reference(u)[-1]).max() > 1e-2


def test_variable_step_sizes_agree(fmu2_path):
    """Ten 2.5 s steps give the same levels as one 25 s step (error control, not luck)."""
    u = random_inputs(40, seed=3)
    coarse = run_cs(fmu2_path, u)
    fine = run_cs(fmu2_path, np.repeat(u, 10, axis=0), ts=2.5)[::10]
    assert np.abs(coarse - fine).max() < 1e-8
