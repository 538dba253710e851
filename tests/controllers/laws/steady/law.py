"""The toy law's step: the equilibrium input of the set-point."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.laws.base import LawContext, LawStep, StepRecord


def build(ctx: LawContext) -> tuple[Any, list[str]]:
    """The law on a tracking FHOCP of the design (zero observer gains): certified as the
    design's certificate is."""
    from controllers.certification.certificates import compute_certificate
    from controllers.laws.tracking.reference import ArtificialSteadyState
    from controllers.ocp.fhocp import FHOCP

    cert = compute_certificate(ctx.model, gain_scale=0.0, **ctx.kwargs)
    fhocp = FHOCP.from_certificate(cert, reference=ArtificialSteadyState(1.0, 0.05),
                                   **ctx.fhocp_options)
    return SteadyLaw(ctx.model, cert, fhocp), []


class SteadyLaw:
    """``u = ū(ȳ)`` (module docstring)."""

    name = "steady"
    #: no operator limits on its outputs, no output out of its cost (controllers.mpc_operating)
    output_limits = False

    def __init__(self, model: Any, cert: Any, fhocp: Any, certified: bool = True) -> None:
        self.model, self.cert, self.fhocp, self.certified = model, cert, fhocp, certified
        self.reset()

    records = property(lambda self: self._records)
    alpha = property(lambda self: float("nan"))
    steady_state = property(lambda self: self._x)

    def reset(self) -> None:
        self._records: list[StepRecord] = []
        self._x: np.ndarray | None = None

    def step(self, observer: Any, y: np.ndarray, y_ref: np.ndarray, t: float,
             x_start: np.ndarray | None = None) -> LawStep:
        from controllers.equilibrium import equilibrium_for_output
        from controllers.ocp.fhocp_result import FHOCPResult

        x, u = equilibrium_for_output(self.model.params, y_ref, self.fhocp.kernel)
        u = np.clip(u, -1.0, 1.0)
        self._x = x
        N = self.fhocp.N
        res = FHOCPResult(np.tile(u, (N, 1)), np.tile(x, (N + 1, 1)), 0.0, "optimal", True)
        rec = StepRecord(u=u, result=res, fallback=False)
        self._records.append(rec)
        return LawStep(rec)

    def disturbance_moved(self, measured: str) -> None:
        """Nothing: the next step's equilibrium holds the disturbances now measured."""

    def restart(self) -> None:
        """Nothing to start again."""

    def setpoint_reason(self, y: np.ndarray) -> str:
        return ""

    def uncertified(self, cert: Any, reason: str) -> SteadyLaw:
        return SteadyLaw(self.model, cert, self.fhocp, certified=False)

    def summary(self) -> dict[str, Any]:
        return {"steady_steps": len(self._records)}

    def settings(self) -> list[Any]:
        return []

    def refuse(self, name: str, value: float) -> str:
        return "the steady-state law has no settings"

    def set(self, name: str, value: float) -> str:
        raise AssertionError("never called: it has no settings")

    def applied(self, u: np.ndarray) -> None:
        """Nothing: its next input does not depend on the last."""

    def control(self, controlled: np.ndarray) -> str:
        raise AssertionError("never called: output_limits is False")
