"""The simulation error of a GRU (``eq:gru``) over windows of a record, with its gradient.

Identification by simulation error needs, at every optimiser step, the model's free-run
outputs over every training window and the gradient of the squared error with respect to the
weights and to each window's initial state. Written with torch's autograd, one step of the
recurrence is some forty tensor operations of a few microseconds each, whatever the model's
size: 0.3 s for 800 steps of a 16-state GRU. ``sim_loss.c`` beside this file computes the
same loss and gradient by backpropagation through time in C (one library for every model,
its dimensions are arguments), some hundred times faster; torch's autograd of the same
rollout (:func:`torch_loss`) is the reference it is tested against and the fallback when no C
compiler is found (``GRU_MPC_KERNEL=0`` forces it).

The loss is ``Σ w (ξ − y)²`` over the windows' samples, with ``w`` a weight per sample and
output (0: left out), except at a sensor limit (:mod:`controllers.identification.saturation`):
where the measured output sits at its upper limit an output above it is no error, at its
lower limit one below it.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from controllers.gru import PARAM_NAMES

__all__ = ["SimLoss", "library", "pack", "torch_loss", "unpack"]

SOURCE = Path(__file__).with_name("sim_loss.c")
CFLAGS = ("-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-std=gnu99")
_LOCK = threading.Lock()
_LIB: dict[str, Any] = {}


def pack(params: Mapping[str, np.ndarray]) -> np.ndarray:
    """The weights as one vector, in the model file's order (:data:`controllers.gru.
    PARAM_NAMES`, each row-major)."""
    return np.concatenate([np.asarray(params[k], dtype=float).ravel() for k in PARAM_NAMES])


def unpack(vector: np.ndarray, n: int, m: int, p: int) -> dict[str, np.ndarray]:
    """The inverse of :func:`pack` for a GRU of ``n`` states, ``m`` inputs, ``p`` outputs."""
    shapes = {"W_z": (n, m), "U_z": (n, n), "b_z": (n,), "W_r": (n, m), "U_r": (n, n),
              "b_r": (n,), "W_h": (n, m), "U_h": (n, n), "b_h": (n,), "U_o": (p, n),
              "b_o": (p,)}
    out, k = {}, 0
    for name in PARAM_NAMES:
        size = int(np.prod(shapes[name]))
        out[name] = np.asarray(vector[k:k + size], dtype=float).reshape(shapes[name])
        k += size
    return out


def library() -> Any | None:
    """The compiled ``sim_loss.c`` (cached in the kernels' folder), or ``None`` when it
    cannot be built here (no compiler, ``GRU_MPC_KERNEL=0``)."""
    if os.environ.get("GRU_MPC_KERNEL", "1") == "0":
        return None
    cc = os.environ.get("CC") or "gcc"
    if shutil.which(cc) is None:
        return None
    from controllers.kernel.cbuild import compile_library, compiler_id, default_cache_dir

    with _LOCK:
        if cc in _LIB:
            return _LIB[cc]
        src = SOURCE.read_text(encoding="utf-8")
        key = hashlib.sha256("\0".join([compiler_id(cc), " ".join(CFLAGS), src]).encode()
                             ).hexdigest()[:16]
        cdir = default_cache_dir()
        so = cdir / f"sl{key}.so"
        lib = None
        if so.exists() or compile_library(src, cdir, f"sl{key}", cc, CFLAGS) is None:
            try:
                lib = ctypes.CDLL(str(so))
            except OSError:
                lib = None
        if lib is not None:
            dp = ctypes.POINTER(ctypes.c_double)
            lib.sl_loss.restype = ctypes.c_double
            lib.sl_loss.argtypes = [ctypes.c_int] * 5 + [dp] * 5 + [
                ctypes.POINTER(ctypes.c_int8), dp, dp, dp]
            lib.sl_size.restype = ctypes.c_long
            lib.sl_size.argtypes = [ctypes.c_int] * 3
        _LIB[cc] = lib
        return lib


def _ptr(a: np.ndarray | None, ctype: Any = ctypes.c_double) -> Any:
    return None if a is None else a.ctypes.data_as(ctypes.POINTER(ctype))


class SimLoss:
    """The simulation loss of fixed windows, evaluated at any weights and initial states.

    Parameters
    ----------
    u : (B, T, m) array
        Normalised inputs of ``B`` windows of ``T`` steps.
    y : (B, T, p) array
        Normalised measured outputs.
    weight : (B, T, p) array, optional
        Weight of each sample and output (default ones; 0: not in the loss).
    sat : (B, T, p) int array, optional
        Sensor-limit flags: +1 where ``y`` is at its upper limit, −1 at its lower one.
    backend : {"auto", "c", "torch"}
        ``"auto"``: the C library when it can be built, else torch.
    """

    def __init__(self, u: np.ndarray, y: np.ndarray, weight: np.ndarray | None = None,
                 sat: np.ndarray | None = None, backend: str = "auto") -> None:
        self.u = np.ascontiguousarray(u, dtype=float)
        self.y = np.ascontiguousarray(y, dtype=float)
        B, T, _ = self.u.shape
        if self.y.shape[:2] != (B, T):
            raise ValueError(f"u has shape {self.u.shape} but y {self.y.shape}")
        self.weight = (np.ones_like(self.y) if weight is None
                       else np.ascontiguousarray(weight, dtype=float))
        self.sat = None if sat is None else np.ascontiguousarray(sat, dtype=np.int8)
        self.lib = library() if backend in ("auto", "c") else None
        if backend == "c" and self.lib is None:
            raise RuntimeError("the simulation-loss library cannot be built here")

    @property
    def backend(self) -> str:
        """``"c"`` or ``"torch"``."""
        return "c" if self.lib is not None else "torch"

    def __call__(self, params: Mapping[str, np.ndarray], x0: np.ndarray, grad: bool = True,
                 outputs: bool = False) -> dict[str, Any]:
        """``{"loss", "grad" (packed, with grad), "grad_x0" (B × n), "xi" (with outputs)}``
        at the weights ``params`` from the initial states ``x0`` (B × n)."""
        n, m = np.shape(params["W_z"])
        p = np.shape(params["U_o"])[0]
        B, T, _ = self.u.shape
        x0 = np.ascontiguousarray(x0, dtype=float).reshape(B, n)
        if self.lib is None:
            return torch_loss(params, x0, self.u, self.y, self.weight, self.sat, grad, outputs)
        P = pack(params)
        gP = np.empty_like(P) if grad else None
        gx0 = np.empty_like(x0) if grad else None
        xi = np.empty_like(self.y) if outputs else None
        loss = self.lib.sl_loss(n, m, p, T, B, _ptr(P), _ptr(x0), _ptr(self.u), _ptr(self.y),
                                _ptr(self.weight), _ptr(self.sat, ctypes.c_int8), _ptr(gP),
                                _ptr(gx0), _ptr(xi))
        if not np.isfinite(loss) and np.all(np.isfinite(P)):
            raise MemoryError("the simulation-loss library could not allocate its scratch")
        out: dict[str, Any] = {"loss": float(loss)}
        if grad:
            out["grad"], out["grad_x0"] = gP, gx0
        if outputs:
            out["xi"] = xi
        return out


def torch_loss(params: Mapping[str, np.ndarray], x0: np.ndarray, u: np.ndarray,
               y: np.ndarray, weight: np.ndarray, sat: np.ndarray | None, grad: bool = True,
               outputs: bool = False) -> dict[str, Any]:
    """:class:`SimLoss` by torch's autograd of the rollout of ``eq:gru``
    (:mod:`controllers.gru`): the reference of the C library, and its fallback."""
    import torch

    from controllers import gru

    dt = torch.float64
    P = {k: torch.tensor(np.asarray(v, dtype=float), dtype=dt, requires_grad=grad)
         for k, v in params.items()}
    X0 = torch.tensor(np.asarray(x0, dtype=float).T.copy(), dtype=dt, requires_grad=grad)
    q = {k: (v.reshape(-1, 1) if k.startswith("b") else v) for k, v in P.items()}
    U = torch.tensor(np.asarray(u, dtype=float), dtype=dt)
    Y = torch.tensor(np.asarray(y, dtype=float), dtype=dt)
    W = torch.tensor(np.asarray(weight, dtype=float), dtype=dt)
    ops = gru.torch_ops()
    x, outs = X0, []
    for t in range(U.shape[1]):
        outs.append(gru.output(q, x).T)            # (B, p)
        if t < U.shape[1] - 1:
            x = gru.step(q, x, U[:, t, :].T, ops)
    xi = torch.stack(outs, dim=1)                 # (B, T, p)
    e = xi - Y
    if sat is not None:
        S = torch.tensor(np.asarray(sat), dtype=torch.int8)
        e = torch.where(((S > 0) & (e > 0)) | ((S < 0) & (e < 0)), torch.zeros_like(e), e)
    loss = (W * e * e).sum()
    out: dict[str, Any] = {"loss": float(loss.item())}
    if grad:
        loss.backward()
        out["grad"] = np.concatenate([P[k].grad.numpy().ravel() for k in PARAM_NAMES])
        out["grad_x0"] = X0.grad.numpy().T.copy()
    if outputs:
        out["xi"] = xi.detach().numpy().copy()
    return out
