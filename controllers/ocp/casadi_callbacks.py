"""The bridge between numpy code and casadi solvers: callbacks on zero-copy buffers.

A solver asks for ``f``, ``∇f``, ``g``, ``∂g/∂w`` and the Hessian of the Lagrangian; the
project computes them with numpy (:mod:`controllers.ocp.nlp_single_shooting`). A
:class:`NumpyCallback` is a casadi ``Function`` whose evaluation calls a Python function on
numpy views of casadi's own argument and result buffers (converting numpy arrays to and from
``DM`` costs about 0.2 ms per 76×31 matrix).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["NumpyCallback", "bind_buffers", "quiet_stdout"]


#: The redirection of file descriptor 1 shared by every thread inside :func:`quiet_stdout`:
#: ``[devnull fd, saved fd, depth]`` (fd 1 is process-wide: the first thread in redirects it,
#: the last one out restores it).
_QUIET: list[int] = [-1, -1, 0]
_QUIET_LOCK = threading.Lock()


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence the C-level standard output (file descriptor 1) for the block (~5 µs).

    qpOASES prints its licence banner when a solver is built or its memory allocated, and
    prints its errors (an infeasible QP inside an SQP iteration, which the SQP handles) to
    standard output whatever its ``printLevel``: every solve runs in this block. Safe from
    several threads at once (a campaign worker with two threads): fd 1 is redirected while
    any thread is inside a block and restored when the last one leaves.
    """
    with _QUIET_LOCK:
        if _QUIET[2] == 0:
            if _QUIET[0] < 0:
                _QUIET[0] = os.open(os.devnull, os.O_WRONLY)
            sys.stdout.flush()
            _QUIET[1] = os.dup(1)
            os.dup2(_QUIET[0], 1)
        _QUIET[2] += 1
    try:
        yield
    finally:
        with _QUIET_LOCK:
            _QUIET[2] -= 1
            if _QUIET[2] == 0:
                os.dup2(_QUIET[1], 1)
                os.close(_QUIET[1])
                _QUIET[1] = -1


class NumpyCallback(ca.Callback):
    """A casadi function evaluated by numpy code (dense inputs, given output sparsity).

    Parameters
    ----------
    name : str
        The casadi function name (solvers look some up: ``nlp_jac_fg``, ``nlp_hess_l``).
    fn : callable
        ``fn(*inputs) -> outputs``: numpy arrays in, arrays (any shape, raveled in column
        order into the output's nonzeros) out.
    sp_in, sp_out : list of casadi.Sparsity
    names_in, names_out : list of str
    """

    def __init__(self, name: str, fn: Callable[..., Any], sp_in: list, sp_out: list,
                 names_in: list[str], names_out: list[str]) -> None:
        ca.Callback.__init__(self)
        self._fn, self._sp_in, self._sp_out = fn, sp_in, sp_out
        self._names_in, self._names_out = names_in, names_out
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._sp_in)

    def get_n_out(self) -> int:
        return len(self._sp_out)

    def get_sparsity_in(self, i: int) -> Any:
        return self._sp_in[i]

    def get_sparsity_out(self, i: int) -> Any:
        return self._sp_out[i]

    def get_name_in(self, i: int) -> str:
        return self._names_in[i]

    def get_name_out(self, i: int) -> str:
        return self._names_out[i]

    def has_eval_buffer(self) -> bool:
        return True

    def eval_buffer(self, arg: list, res: list) -> int:
        # zero-copy views of casadi's buffers
        ins = [np.zeros(sp.nnz()) if a is None else np.frombuffer(a, dtype=float,
                                                                    count=sp.nnz())
               for a, sp in zip(arg, self._sp_in, strict=True)]
        outs = self._fn(*ins)
        for r, o in zip(res, outs, strict=True):
            if r is not None:
                np.frombuffer(r, dtype=float)[:] = np.ravel(o, order="F")
        return 0


def bind_buffers(solver: Any) -> tuple:
    """Bind numpy arrays to the solver's zero-copy argument and result buffers (converting
    numpy arrays to and from ``DM`` costs tens of microseconds per vector)."""
    buf, trigger = solver.buffer()
    ins = {name: np.zeros(solver.sparsity_in(i).nnz())
           for i, name in enumerate(solver.name_in())}
    outs = {name: np.zeros(solver.sparsity_out(i).nnz())
            for i, name in enumerate(solver.name_out())}
    for i, name in enumerate(solver.name_in()):
        buf.set_arg(i, memoryview(ins[name]))
    for i, name in enumerate(solver.name_out()):
        buf.set_res(i, memoryview(outs[name]))
    return buf, trigger, ins, outs
