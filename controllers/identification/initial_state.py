"""The initial state of a record, estimated from its first samples, and free-run simulation.

A logged experiment does not start at a known state: the plant was somewhere when logging
began. Starting the model at ``x = 0`` (or at the equilibrium of the first sample) makes the
first part of every simulation a transient of the model's own, which on a short record is a
large share of it, and which a δISS model forgets only over its own time constants. Here the
initial state is estimated instead, from the first ``K`` samples (:data:`DEFAULT_SAMPLES`):

    x̂_0 = argmin_{x_0 ∈ [−1, 1]ⁿ} Σ_{t<K} (ξ_t(x_0) − y_t)² + λ ‖x_0 − x_c‖²

with ``ξ_t(x_0)`` the model's free run from ``x_0`` (``eq:gru``; GRU states stay in
[−1, 1]), ``x_c`` the model's steady state for the first input and ``λ`` small
(:data:`PRIOR_WEIGHT`), by L-BFGS-B on the gradient of :mod:`controllers.identification.
sim_loss`. The rest of the experiment is then a free run from ``x̂_0``: the model sees the
measured outputs of its first ``K`` samples only, through ``x̂_0``. Samples at a sensor limit
are treated as in training (:mod:`controllers.identification.saturation`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from controllers.identification.sim_loss import SimLoss

__all__ = ["DEFAULT_SAMPLES", "PRIOR_WEIGHT", "estimate_initial_state", "free_run",
           "steady_state_guess"]

#: Samples of an experiment used to estimate its initial state.
DEFAULT_SAMPLES = 50
#: Weight of ``‖x_0 − x_c‖²`` against the squared errors (normalised units).
PRIOR_WEIGHT = 1e-3


def steady_state_guess(params: Mapping[str, np.ndarray], u0: np.ndarray,
                       iterations: int = 300) -> np.ndarray:
    """The model's state after holding ``u0`` for ``iterations`` steps from ``x = 0``: its
    steady state for ``u0`` to a good approximation (a δISS GRU contracts)."""
    from controllers.gru import step

    x = np.zeros(np.shape(params["W_z"])[0])
    u0 = np.asarray(u0, dtype=float)
    for _ in range(iterations):
        x = step(params, x, u0)
    return x


def estimate_initial_state(params: Mapping[str, np.ndarray], u: np.ndarray, y: np.ndarray,
                           sat: np.ndarray | None = None, samples: int = DEFAULT_SAMPLES,
                           prior: np.ndarray | None = None,
                           start: np.ndarray | None = None) -> np.ndarray:
    """``x̂_0`` (module docstring) from the first ``samples`` rows of ``u`` (T, m), ``y``
    (T, p) (normalised) and their sensor-limit flags ``sat``; ``start``: where L-BFGS-B
    starts (default the prior ``x_c``; the last estimate, when the weights have changed
    little since)."""
    from scipy.optimize import minimize

    K = max(1, min(int(samples), len(u)))
    x_c = steady_state_guess(params, u[0]) if prior is None else np.asarray(prior, float)
    loss = SimLoss(u[None, :K], y[None, :K], sat=None if sat is None else sat[None, :K])
    n = x_c.shape[0]

    def fun(x0: np.ndarray) -> tuple[float, np.ndarray]:
        r = loss(params, x0[None, :])
        d = x0 - x_c
        return (r["loss"] + PRIOR_WEIGHT * float(d @ d),
                r["grad_x0"][0] + 2.0 * PRIOR_WEIGHT * d)

    start = np.clip(x_c if start is None else np.asarray(start, dtype=float), -1.0, 1.0)
    res = minimize(fun, start, jac=True, method="L-BFGS-B", bounds=[(-1.0, 1.0)] * n,
                   options={"maxiter": 200})
    return np.asarray(res.x if np.all(np.isfinite(res.x)) else start, dtype=float)


def free_run(params: Mapping[str, np.ndarray], u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """The model's outputs ``ξ_0 … ξ_{T−1}`` (T, p) from ``x0`` under the inputs ``u``."""
    p = np.shape(params["U_o"])[0]
    loss = SimLoss(u[None], np.zeros((1, len(u), p)))
    return loss(params, np.asarray(x0, dtype=float)[None, :], grad=False,
                outputs=True)["xi"][0]
