"""What the operator's settings impose on one solve of the FHOCP (issue 61; docs:
design/operating.md): bounds on the inputs and a narrowing of the output rows.

:class:`controllers.operator.Operator` turns the operator's settings (an input out of
service, an operator limit, the move limit from the input applied last) into an
:class:`OperatorTerms` before each step; :class:`controllers.ocp.fhocp.FHOCP` holds it
(:attr:`~controllers.ocp.fhocp.FHOCP.operator`, ``None``: none, the FHOCP as designed) and
both references write it into the solver's bounds:

- ``u_0 ∈ [lo0, hi0]``: the first input, inside the operator's limits and within ``Δ`` of the
  input applied last (the first row of ``eq:move-constraint``); an input out of service
  has ``lo0 = hi0`` = the value it is held at;
- ``u_i ∈ [lo, hi]`` for ``i ≥ 1`` and the tracking law's ``u_s``: the operator's limits
  (the held value out of service);
- the output rows ``L (U_o x_i + b_o) ≤ h − δ − a_i ê_o − b_i − w_L``: ``δ ≥ 0`` the operator
  limits' narrowing of ``h`` (``eq:operator-rows``), and the same ``h − δ`` wherever the law
  derives from ``h`` (the tracking law's ``Y_s``).

All normalised; the exported controller's C step builds the same numbers
(``controllers/kernel/controller.h``: ``ctl_ops``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["OperatorTerms"]


@dataclass(frozen=True)
class OperatorTerms:
    """One step's operator terms (module docstring).

    Attributes
    ----------
    lo0, hi0 : (m,) arrays
        Bounds of ``u_0``.
    lo, hi : (m,) arrays
        Bounds of ``u_i`` (``i ≥ 1``) and of ``u_s``.
    narrowing : (q,) array
        ``δ``, the operator limits' narrowing of each row of ``h`` (≥ 0).
    """

    lo0: np.ndarray
    hi0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    narrowing: np.ndarray

    def bound(self, lbx: np.ndarray, ubx: np.ndarray, iu: np.ndarray,
              ius: np.ndarray | None = None) -> None:
        """Intersect the solver's bounds ``lbx``, ``ubx`` (in place) with these: ``iu``
        (N, m) the inputs' indices in ``w``, ``ius`` the tracking law's ``u_s``'s."""
        lbx[iu[0]] = np.maximum(lbx[iu[0]], self.lo0)
        ubx[iu[0]] = np.minimum(ubx[iu[0]], self.hi0)
        rest = iu[1:]
        lbx[rest] = np.maximum(lbx[rest], self.lo)
        ubx[rest] = np.minimum(ubx[rest], self.hi)
        if ius is not None:
            lbx[ius] = np.maximum(lbx[ius], self.lo)
            ubx[ius] = np.minimum(ubx[ius], self.hi)

    def clip(self, u: np.ndarray) -> np.ndarray:
        """A plan ``u`` (N, m) inside these bounds (an initial guess)."""
        out = np.array(u, dtype=float)
        out[0] = np.minimum(np.maximum(out[0], self.lo0), self.hi0)
        out[1:] = np.minimum(np.maximum(out[1:], self.lo), self.hi)
        return out
