"""The contraction cap derived from the data (``controllers.identification.contraction``): the
ARX baseline's slowest pole, and the cap it allows."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.identification.contraction import RHO_FLOOR, SLACK, rho_max, slowest_pole
from controllers.identification.linear import ARXModel


def arx(poles: list[float]) -> ARXModel:
    """A SISO ARX model whose autoregressive part has these (real) poles."""
    a = -np.poly(poles)[1:]           # y_t = Σ a_i y_{t−i} + ...
    theta = np.concatenate([[0.1], a, [0.5]]).reshape(-1, 1)
    return ARXModel(len(poles), 1, 1, theta)


def test_the_slowest_pole_and_the_cap_it_allows() -> None:
    assert slowest_pole(arx([0.5, 0.94])) == pytest.approx(0.94)
    assert rho_max(arx([0.5, 0.94])) == pytest.approx(1 - 0.06 / SLACK)
    assert rho_max(arx([0.2])) == RHO_FLOOR                   # a fast plant: the floor
    assert rho_max(arx([0.999])) == pytest.approx(0.9995)     # a slow one: slower still
    assert rho_max(arx([1.01])) == 0.0 and rho_max(None) == 0.0   # not stable: no cap


def test_a_two_output_model_reads_the_poles_of_both() -> None:
    """``p = 2``, ``na = 1``: the companion matrix is ``A_1`` itself."""
    A1 = np.array([[0.9, 0.05], [0.0, 0.6]])
    theta = np.vstack([np.zeros((1, 2)), A1.T, np.ones((1, 2))])
    assert slowest_pole(ARXModel(1, 1, 1, theta)) == pytest.approx(0.9)
