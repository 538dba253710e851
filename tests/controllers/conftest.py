"""Shared fixtures of the numerical-core tests: the certified random test problem, built once."""

from __future__ import annotations

import numpy as np
import pytest

from tests.controllers.random_gru import certified_random_problem

#: Set-points (normalised) at which every hypothesis of th:feasibility-stability must hold for
#: the shared test problem: those the FHOCP and the governor tests move between.
SETPOINTS = [np.array([0.1, 0.1]), np.array([-0.1, -0.1]), np.array([0.0, 0.05])]


@pytest.fixture(scope="session")
def problem() -> tuple:
    """``(model, certificate)`` of :func:`certified_random_problem` at :data:`SETPOINTS`."""
    return certified_random_problem(SETPOINTS)


@pytest.fixture(scope="session")
def model(problem: tuple):
    return problem[0]


@pytest.fixture(scope="session")
def cert(problem: tuple):
    return problem[1]
