"""The GRU model of the paper, ``eq:gru``, written once for numpy, casadi and torch.

    z_k   = σ(W_z u_k + U_z x_k + b_z)
    r_k   = σ(W_r u_k + U_r x_k + b_r)
    h_k   = tanh(W_h u_k + U_h (r_k ∘ x_k) + b_h)      (reset gate *before* U_h)
    x_k+1 = z_k ∘ x_k + (1 − z_k) ∘ h_k
    ξ_k   = U_o x_k + b_o

This is not torch.nn.GRU's convention (which applies the reset gate after U_h and swaps the
roles of z and 1 − z). The functions below use only ``@``, ``*``, ``+``, ``-`` and the two
activations passed in ``ops``, so the same source runs on numpy arrays, casadi SX/MX/DM and
torch tensors (column convention: ``x`` is ``(n,)`` or ``(n, batch)``; biases must then be
``(n, 1)``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NUMPY_OPS", "PARAM_NAMES", "WEIGHT_LIMIT", "Ops", "casadi_ops", "dimensions",
           "gates", "output", "simulate", "step", "torch_ops"]

#: Names of the trainable arrays, in the model file's order.
PARAM_NAMES = ("W_z", "U_z", "b_z", "W_r", "U_r", "b_r", "W_h", "U_h", "b_h", "U_o", "b_o")
#: The plausible magnitude of a weight or bias of ``eq:gru`` (in normalised units): trained
#: models hold weights of order one to a few hundred; beyond this a model file, or the
#: controller FMU's data file, is damaged or edited, and is refused.
WEIGHT_LIMIT = 1e6


@dataclass(frozen=True)
class Ops:
    """Element-wise activations of one numerical backend."""

    sigmoid: Callable[[Any], Any]
    tanh: Callable[[Any], Any]


def _np_sigmoid(v: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-v))


NUMPY_OPS = Ops(sigmoid=_np_sigmoid, tanh=np.tanh)


def casadi_ops() -> Ops:
    """Activations for casadi symbols (SX, MX, DM)."""
    import casadi as ca

    return Ops(sigmoid=lambda v: 1.0 / (1.0 + ca.exp(-v)), tanh=ca.tanh)


def torch_ops() -> Ops:
    """Activations for torch tensors (training only)."""
    import torch

    return Ops(sigmoid=torch.sigmoid, tanh=torch.tanh)


def gates(p: Mapping[str, Any], x: Any, u: Any, ops: Ops, dz: Any = 0.0, dr: Any = 0.0):
    """Return ``(z, r, h)`` of ``eq:gru``; ``dz``/``dr`` are extra gate inputs.

    The observer ``eq:observer`` uses ``dz = L_z (y − ŷ)`` and ``dr = L_r (y − ŷ)``; the
    model itself uses zero.
    """
    z = ops.sigmoid(p["W_z"] @ u + p["U_z"] @ x + p["b_z"] + dz)
    r = ops.sigmoid(p["W_r"] @ u + p["U_r"] @ x + p["b_r"] + dr)
    h = ops.tanh(p["W_h"] @ u + p["U_h"] @ (r * x) + p["b_h"])
    return z, r, h


def step(p: Mapping[str, Any], x: Any, u: Any, ops: Ops = NUMPY_OPS, dz: Any = 0.0,
         dr: Any = 0.0) -> Any:
    """State update ``x_{k+1} = f(x_k, u_k)`` of ``eq:gru`` (``eq:observer`` with dz, dr)."""
    z, _, h = gates(p, x, u, ops, dz, dr)
    return z * x + (1 - z) * h


def output(p: Mapping[str, Any], x: Any) -> Any:
    """Output map ``ξ_k = g(x_k) = U_o x_k + b_o`` of ``eq:gru``."""
    return p["U_o"] @ x + p["b_o"]


def simulate(p: Mapping[str, np.ndarray], x0: np.ndarray, u: np.ndarray) -> tuple[np.ndarray,
                                                                                   np.ndarray]:
    """Open-loop simulation with numpy.

    Parameters
    ----------
    p : mapping of arrays
        GRU weights (:data:`PARAM_NAMES`).
    x0 : (n,) array
        Initial state.
    u : (T, m) array
        Normalised inputs.

    Returns
    -------
    x : (T + 1, n) array
        States ``x_0 … x_T``.
    xi : (T, p) array
        Outputs ``ξ_0 … ξ_{T-1}``.
    """
    x = np.empty((u.shape[0] + 1, x0.shape[0]))
    x[0] = x0
    for k in range(u.shape[0]):
        x[k + 1] = step(p, x[k], u[k])
    xi = x[:-1] @ p["U_o"].T + p["b_o"]
    return x, xi


def dimensions(p: Mapping[str, np.ndarray]) -> tuple[int, int, int]:
    """Return ``(n, m, p)``: states, inputs, outputs."""
    n, m = np.shape(p["W_z"])
    return n, m, np.shape(p["U_o"])[0]
