"""The one-source GRU (``eq:gru``): numpy, casadi and torch give the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import gru

N, M, P = 7, 2, 2


def random_params(seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    shapes = {"W_z": (N, M), "U_z": (N, N), "b_z": (N,), "W_r": (N, M), "U_r": (N, N),
              "b_r": (N,), "W_h": (N, M), "U_h": (N, N), "b_h": (N,), "U_o": (P, N),
              "b_o": (P,)}
    return {k: rng.normal(size=s) for k, s in shapes.items()}


def numpy_rollout(p, x0, us, dz=None, dr=None):
    xs, x = [], x0
    for k, u in enumerate(us):
        x = gru.step(p, x, u, gru.NUMPY_OPS, 0.0 if dz is None else dz[k],
                     0.0 if dr is None else dr[k])
        xs.append(x)
    return np.array(xs)


def test_step_matches_hand_written_equations():
    p = random_params(1)
    rng = np.random.default_rng(2)
    x, u = rng.uniform(-1, 1, N), rng.uniform(-1, 1, M)

    def sig(v):
        return 1 / (1 + np.exp(-v))

    z = sig(p["W_z"] @ u + p["U_z"] @ x + p["b_z"])
    r = sig(p["W_r"] @ u + p["U_r"] @ x + p["b_r"])
    h = np.tanh(p["W_h"] @ u + p["U_h"] @ (r * x) + p["b_h"])
    expected = z * x + (1 - z) * h
    assert np.allclose(gru.step(p, x, u), expected, rtol=0, atol=1e-15)
    assert np.allclose(gru.output(p, x), p["U_o"] @ x + p["b_o"], rtol=0, atol=1e-15)


def test_casadi_sx_function_agrees_with_numpy():
    ca = pytest.importorskip("casadi")
    p = random_params(3)
    rng = np.random.default_rng(4)
    steps = 6
    x0 = rng.uniform(-1, 1, N)
    us = rng.uniform(-1, 1, (steps, M))
    dz = rng.normal(scale=0.3, size=(steps, N))
    dr = rng.normal(scale=0.3, size=(steps, N))

    x_sym = ca.SX.sym("x", N)
    u_sym = ca.SX.sym("u", M)
    dz_sym = ca.SX.sym("dz", N)
    dr_sym = ca.SX.sym("dr", N)
    ops = gru.casadi_ops()
    f = ca.Function("f", [x_sym, u_sym, dz_sym, dr_sym],
                    [gru.step(p, x_sym, u_sym, ops, dz_sym, dr_sym)])
    g = ca.Function("g", [x_sym], [gru.output(p, x_sym)])

    for with_corr in (False, True):
        ref = numpy_rollout(p, x0, us, dz if with_corr else None, dr if with_corr else None)
        x = x0
        for k in range(steps):
            x = np.array(f(x, us[k], dz[k] if with_corr else np.zeros(N),
                           dr[k] if with_corr else np.zeros(N))).ravel()
            assert np.max(np.abs(x - ref[k])) < 1e-12
            xi = np.array(g(x)).ravel()
            assert np.max(np.abs(xi - gru.output(p, ref[k]))) < 1e-12
    # The corrections matter: without them the trajectory is different.
    assert np.max(np.abs(numpy_rollout(p, x0, us) - numpy_rollout(p, x0, us, dz, dr))) > 1e-3


def test_torch_batched_agrees_with_numpy():
    torch = pytest.importorskip("torch")
    p = random_params(5)
    rng = np.random.default_rng(6)
    steps, batch = 6, 3
    x0 = rng.uniform(-1, 1, (N, batch))
    us = rng.uniform(-1, 1, (steps, M, batch))
    dz = rng.normal(scale=0.3, size=(steps, N, batch))
    dr = rng.normal(scale=0.3, size=(steps, N, batch))
    pt = {k: torch.tensor(v.reshape(-1, 1) if k.startswith("b") else v, dtype=torch.float64)
          for k, v in p.items()}
    ops = gru.torch_ops()
    x = torch.tensor(x0, dtype=torch.float64)
    for k in range(steps):
        x = gru.step(pt, x, torch.tensor(us[k]), ops, torch.tensor(dz[k]), torch.tensor(dr[k]))
        xi = gru.output(pt, x)
        for b in range(batch):
            ref = numpy_rollout(p, x0[:, b], us[:k + 1, :, b], dz[:k + 1, :, b],
                                dr[:k + 1, :, b])[-1]
            assert np.max(np.abs(x[:, b].numpy() - ref)) < 1e-12
            assert np.max(np.abs(xi[:, b].numpy() - gru.output(p, ref))) < 1e-12


def test_simulate_returns_states_and_outputs():
    p = random_params(7)
    rng = np.random.default_rng(8)
    us = rng.uniform(-1, 1, (5, M))
    x, xi = gru.simulate(p, np.zeros(N), us)
    assert x.shape == (6, N) and xi.shape == (5, P)
    assert np.allclose(x[1:], numpy_rollout(p, np.zeros(N), us), atol=1e-15)
    assert np.allclose(xi[3], gru.output(p, x[3]), atol=1e-15)
    assert gru.dimensions(p) == (N, M, P)
