"""What one solve of the FHOCP is asked for: the law's part of
:meth:`controllers.ocp.fhocp.FHOCP.solve_request` (``eq:optimization``).

The solve procedure is one for every law (the ``i = 0`` row, the solver, the independent
answer check, the judge, the warm start); a law hands it a :class:`SolveRequest`: the
paper's :class:`Setpoint` here, the tracking law's
:class:`controllers.ocp.fhocp_tracking.Target`. A third law (say offset-free with a
disturbance model) brings its own request class.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP
    from controllers.ocp.fhocp_result import FHOCPResult

__all__ = ["Setpoint", "SolveRequest"]


class SolveRequest(Protocol):
    """What one solve is asked for: the law's part of :meth:`FHOCP.solve_request` (the
    paper's set-point, :class:`Setpoint`; the tracking law's target and candidate,
    :class:`controllers.ocp.fhocp_tracking.Target`). A third law brings its own."""

    def candidate(self, fhocp: Any, x_hat: np.ndarray, e_o: float, status: str
                  ) -> FHOCPResult:
        """The law's candidate, evaluated, with ``status`` (reported when ``x̂`` fails the
        ``i = 0`` row and no solver is called)."""
        ...

    def write(self, fhocp: Any, ins: dict[str, np.ndarray], x_hat: np.ndarray,
              e_o: float) -> None:
        """The solver's parameters, bounds and initial guess (its argument buffers)."""
        ...

    def check(self, fhocp: Any, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray,
              e_o: float, status: str) -> FHOCPResult:
        """The independent check of the solver's answer ``wopt`` (solver status
        ``status``)."""
        ...


@dataclass(frozen=True)
class Setpoint:
    """The paper's request (``eq:optimization``): the set-point ``(x̄, ū)``, the terminal
    radius α, the initial inputs (``None``: the previous solution shifted with ``ū``
    appended when ``warm``, else ``ū``) and ``u_{−1}``."""

    x_bar: np.ndarray
    u_bar: np.ndarray
    alpha: float
    u_init: np.ndarray | None
    warm: bool
    u_prev: np.ndarray

    def candidate(self, fhocp: FHOCP, x_hat: np.ndarray, e_o: float, status: str
                  ) -> FHOCPResult:
        res = fhocp.candidate(x_hat, np.tile(self.u_bar, (fhocp.N, 1)), self.x_bar,
                              self.u_bar, e_o, self.alpha, self.u_prev)
        res.status = status
        return res

    def write(self, fhocp: FHOCP, ins: dict[str, np.ndarray], x_hat: np.ndarray,
              e_o: float) -> None:
        fhocp.layout.write(ins, fhocp.tightened_bounds(e_o), x_hat, self.x_bar, self.u_bar,
                           self.alpha, self.u_init, fhocp._warm if self.warm else None,
                           fhocp.warm_duals, fhocp.rollout,
                           self.u_prev if fhocp.has_du else None)

    def check(self, fhocp: FHOCP, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray,
              e_o: float, status: str) -> FHOCPResult:
        return fhocp.check_answer(wopt, pv, x_hat, e_o, self.x_bar, self.u_bar, self.alpha,
                                  self.u_prev, status)
