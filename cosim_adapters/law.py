"""What a control law of the ``robust-mpc`` component is: the protocol both laws implement.

:class:`cosim_adapters.robust_mpc.RobustMPCController` owns the observer, the units and the
certificate grade; everything that differs between laws -- the set-point handling, the
optimal-control problem and its reference, the law's own state and statistics -- lives in one
object implementing :class:`ControlLaw`: :class:`cosim_adapters.paper_law.PaperLaw` (the
paper's regulation law, ``eq:mpc``, with its governor) and :class:`cosim_adapters.tracking.
TrackingLaw` (the artificial steady state of MPC for tracking). A third law (say,
offset-free with a disturbance model) is one new class with these methods, registered in
:data:`cosim_adapters.mpc_options.LAWS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

__all__ = ["ControlLaw", "LawStep", "setpoint_text"]


@dataclass
class LawStep:
    """One step of a law: the step record (:class:`controllers.ocp.paper_mpc.StepRecord`),
    whether the requested set-point was refused, the fraction of the way to it the reference
    governor moved (1: no governor, or all the way), and the law's own diagnostics (by
    name, in the problem's units)."""

    record: Any
    rejected: bool = False
    diagnostics: dict[str, float] = field(default_factory=dict)
    governor_lambda: float = 1.0


def setpoint_text(model: Any, y: np.ndarray) -> str:
    """``"set-point CA=0.5 mol/L, T=345 K"``: the normalised ``y`` in the problem's names and
    units (``model.problem``'s)."""
    problem = model.problem
    return "set-point " + ", ".join(f"{n}={v:.4g} {u}".rstrip() for n, v, u in zip(
        problem.output_names, model.denormalize_y(y), problem.output_units, strict=True))


class ControlLaw(Protocol):
    """A control law of the robust MPC (module docstring); normalised units throughout."""

    #: the option value that selects it (``law="paper"``, ``law="tracking"``)
    name: str
    #: its optimal-control problem (``eq:optimization`` and its reference)
    fhocp: Any
    #: the certificate its tightening comes from
    cert: Any

    @property
    def records(self) -> list[Any]:
        """The step records of the run so far."""
        ...

    @property
    def alpha(self) -> float:
        """The terminal radius in use (``eq:def-alpha``)."""
        ...

    def reset(self) -> None:
        """Forget the run (set-points, plans, statistics)."""
        ...

    def step(self, observer: Any, y: np.ndarray, y_ref: np.ndarray, t: float,
             x_start: np.ndarray | None = None) -> LawStep:
        """``u_k`` for the measured ``y`` and the requested ``ȳ``, at ``x̂`` and ``ê_o`` of
        ``observer`` (which the controller advances afterwards); ``x_start``: the state the
        FHOCP starts from instead of ``x̂`` (``x̂`` predicted over the inputs' dead time,
        :mod:`controllers.dead_time`)."""
        ...

    def disturbance_moved(self, measured: str) -> None:
        """The measured disturbances the FHOCP holds moved (the model's biases hold the new
        values, :class:`controllers.disturbances.BiasShift`; ``measured``: them in the user's
        names and units, for messages): the law's equilibria follow."""
        ...

    def restart(self) -> None:
        """After a fallback whose candidate was infeasible with disturbances measured: what
        the law starts again from (the tracking law: its steady state)."""
        ...

    def setpoint_reason(self, y: np.ndarray) -> str:
        """Why the certified design does not cover the set-point ``y``, one line naming it
        (:func:`setpoint_text`; empty: it does)."""
        ...

    def uncertified(self, cert: Any, reason: str) -> ControlLaw:
        """The same law on the uncertified certificate ``cert`` (its measured tightening);
        raises :class:`cosim.core.errors.CosimError` when even that leaves nothing to control
        (``reason``: why the run is uncertified)."""
        ...

    def summary(self) -> dict[str, Any]:
        """The law's entries of the run summary (its statistics and design)."""
        ...
