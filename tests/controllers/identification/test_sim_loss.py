"""The simulation loss in C (``controllers/identification/sim_loss.c``) against torch's
autograd of the same rollout: loss, gradients, outputs, on several windows with weights and
sensor-limit flags, for GRUs of several shapes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from controllers.identification.sim_loss import SimLoss, library, pack, torch_loss, unpack
from controllers.identification.training import init_params

needs_cc = pytest.mark.skipif(library() is None, reason="no C compiler for sim_loss.c")


def _problem(n: int, m: int, p: int, B: int, T: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    P = init_params(n, m, p, seed)
    P["U_z"] = rng.normal(scale=0.2, size=(n, n))       # every weight has a gradient
    P["U_r"] = rng.normal(scale=0.5, size=(n, n))
    P["b_o"] = rng.normal(size=p)
    u = rng.normal(size=(B, T, m))
    y = rng.normal(size=(B, T, p))
    w = rng.uniform(0.0, 1.0, (B, T, p))
    w[0, -min(5, T - 1):] = 0.0                          # a padded tail
    sat = rng.integers(-1, 2, (B, T, p)).astype(np.int8)
    x0 = rng.uniform(-1, 1, (B, n))
    return P, u, y, w, sat, x0


@needs_cc
@pytest.mark.parametrize("n, m, p, B, T", [(7, 2, 3, 3, 40), (1, 1, 1, 1, 2), (12, 3, 1, 2, 90)])
def test_c_matches_torch_autograd(n: int, m: int, p: int, B: int, T: int) -> None:
    P, u, y, w, sat, x0 = _problem(n, m, p, B, T, seed=n + T)
    c = SimLoss(u, y, w, sat)
    assert c.backend == "c"
    a = c(P, x0, outputs=True)
    b = torch_loss(P, x0, u, y, w, sat, outputs=True)
    assert a["loss"] == pytest.approx(b["loss"], rel=1e-13)
    scale = np.max(np.abs(b["grad"]))
    assert np.max(np.abs(a["grad"] - b["grad"])) <= 1e-12 * scale
    assert np.max(np.abs(a["grad_x0"] - b["grad_x0"])) < 1e-12 * max(1.0, scale)
    assert np.max(np.abs(a["xi"] - b["xi"])) < 1e-13


@needs_cc
def test_sensor_limits_make_one_sided_errors() -> None:
    """At an upper limit an output above the measured value is no error, below it is; no
    flag, both count."""
    P, u, y, _, _, x0 = _problem(4, 1, 1, 1, 30, seed=1)
    xi = SimLoss(u, y)(P, x0, grad=False, outputs=True)["xi"]
    up = np.where(xi > y, 1, 0).astype(np.int8)       # flag where the model is above
    down = np.where(xi < y, 1, 0).astype(np.int8)     # flag where it is below
    plain = SimLoss(u, y)(P, x0)["loss"]
    above = SimLoss(u, y, sat=up)(P, x0)["loss"]
    below = SimLoss(u, y, sat=down)(P, x0)["loss"]
    assert above == pytest.approx(float(np.sum(((xi - y) ** 2)[xi < y])), rel=1e-12)
    assert below == pytest.approx(plain, rel=1e-12)


def test_pack_and_unpack_invert_each_other() -> None:
    P = init_params(5, 2, 3, 0)
    back = unpack(pack(P), 5, 2, 3)
    assert all(np.array_equal(back[k], P[k]) for k in P)


def test_the_torch_fallback_answers_alone() -> None:
    P, u, y, w, sat, x0 = _problem(3, 1, 2, 2, 10, seed=4)
    a = SimLoss(u, y, w, sat, backend="torch")
    assert a.backend == "torch"
    out = a(P, x0, outputs=True)
    assert np.isfinite(out["loss"]) and out["grad"].shape == pack(P).shape
    assert out["xi"].shape == y.shape
