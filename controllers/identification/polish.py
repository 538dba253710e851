"""The last stretch of a candidate's fit: L-BFGS on the whole simulation loss.

Adam (:func:`controllers.identification.simulation.fit_candidate`) finds the basin; it does not
settle in it: at its last learning rate each step still moves the weights by about that rate,
and the free run of a plant that is slow against its sample time is sensitive to them (an
error δ in a pole of modulus λ moves the simulated output by about δ/(1 − λ)² of its swing).
On a nearly linear record (the example air heater, ``fmus/examples/air_heater``: λ = 0.94)
Adam's candidates simulated the validation rows 5× worse than the ARX baseline after 18,000
steps, while L-BFGS from where Adam stopped reached the baseline within 2,000 iterations.

Here the weights before the δISS projection and each training window's initial state are one
vector, the loss is the simulation error over every window at once (``sim_loss.c``'s
gradient, chained by torch through :func:`controllers.identification.training.constrain`, so
that every iterate is δISS, ``th:stability-bonassi``, and within the contraction cap of
``lem:Vs``), the initial states are bounded to the GRU's state box, and scipy's L-BFGS-B
minimises it. The projection's norms are not smooth where two rows tie; a line search that
fails there restarts the method from where it is, at most :data:`RESTARTS` times without
progress. The caller scores the iterates on validation every so often and keeps the best
(Adam's best included), so a polish that does not help costs time, never accuracy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from controllers.identification.sim_loss import SimLoss, unpack

__all__ = ["RESTARTS", "polish"]

#: Restarts of L-BFGS-B after a failed line search that made no progress, at most.
RESTARTS = 3
#: Limited-memory pairs of L-BFGS-B.
MEMORY = 20


class _Flat:
    """The trainable weights and the windows' initial states as one vector and back."""

    def __init__(self, params: dict[str, np.ndarray], windows: int, train_uz: bool) -> None:
        self.keys = [k for k in params if k != "U_z" or train_uz]
        self.shapes = {k: np.shape(params[k]) for k in params}
        self.uz = None if train_uz else np.zeros(self.shapes["U_z"])
        self.n = self.shapes["U_z"][0]
        self.windows = windows
        self.size = sum(int(np.prod(self.shapes[k])) for k in self.keys)

    def pack(self, params: dict[str, np.ndarray], x0: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(params[k], float).ravel() for k in self.keys]
                              + [np.asarray(x0, float).ravel()])

    def unpack(self, v: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        out, i = {}, 0
        for k in self.keys:
            size = int(np.prod(self.shapes[k]))
            out[k] = v[i:i + size].reshape(self.shapes[k])
            i += size
        if self.uz is not None:
            out["U_z"] = self.uz
        return out, v[i:].reshape(self.windows, self.n)

    def bounds(self) -> list[tuple[float | None, float | None]]:
        return [(None, None)] * self.size + [(-1.0, 1.0)] * (self.windows * self.n)


def polish(arrays: tuple[np.ndarray, ...], params: dict[str, np.ndarray], x0: np.ndarray,
           effective: Callable[[dict[str, Any]], dict[str, Any]], train_uz: bool,
           iterations: int, offer: Callable[[int, dict[str, np.ndarray]], bool]) -> int:
    """Minimise the simulation loss of the windows ``arrays`` (``U, Y, W, S`` of
    :func:`controllers.identification.simulation.window_arrays`) from ``params`` (δISS
    weights) and ``x0`` (one initial state per window) by L-BFGS-B, for at most
    ``iterations`` iterations; the iterations done.

    ``effective`` maps torch tensors of the free weights to the weights the model runs
    (:func:`controllers.identification.training.constrain`); ``offer(iteration, weights)`` is
    called after every iteration with the effective weights as numpy arrays, and returns
    ``True`` to stop.
    """
    import torch
    from scipy.optimize import minimize

    U, Y, W, S = arrays
    loss = SimLoss(U, Y, W / W.sum(), S)
    flat = _Flat(params, U.shape[0], train_uz)
    n, m, p = flat.n, U.shape[2], Y.shape[2]

    def weights(v: np.ndarray, grad: bool) -> tuple[dict[str, Any], dict[str, Any], np.ndarray]:
        free, x = flat.unpack(v)
        tensors = {k: torch.tensor(a, dtype=torch.float64, requires_grad=grad and k in
                                   flat.keys) for k, a in free.items()}
        with torch.set_grad_enabled(grad):
            q = effective(tensors)
        return tensors, q, x

    def fun(v: np.ndarray) -> tuple[float, np.ndarray]:
        tensors, q, x = weights(v, True)
        r = loss({k: t.detach().numpy() for k, t in q.items()}, x)
        g = unpack(r["grad"], n, m, p)
        torch.autograd.backward([q[k] for k in flat.keys], [torch.from_numpy(g[k])
                                                            for k in flat.keys])
        return r["loss"], np.concatenate([tensors[k].grad.numpy().ravel() for k in flat.keys]
                                         + [r["grad_x0"].ravel()])

    done, stop = 0, False

    def step(v: np.ndarray) -> None:
        nonlocal done, stop
        done += 1
        q = weights(v, False)[1]
        stop = offer(done, {k: t.detach().numpy().copy() for k, t in q.items()})
        if stop:
            raise StopIteration

    v, stalled = flat.pack(params, x0), 0
    while done < iterations and not stop and stalled <= RESTARTS:
        before, left = done, iterations - done
        res = minimize(fun, v, jac=True, method="L-BFGS-B", bounds=flat.bounds(),
                       callback=step, options={"maxiter": left, "maxfun": 2 * left,
                                               "ftol": 0.0, "gtol": 0.0, "maxcor": MEMORY})
        v = res.x
        stalled = stalled + 1 if done == before else 0
    return done
