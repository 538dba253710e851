"""The toy law in C (``law.c``): no numbers, no parameters, no switches."""

from __future__ import annotations

from typing import Any

from controllers.kernel.controller_source import ControllerDesign


def export_design(law: Any, observer: Any, model: Any, u_lo: Any, u_hi: Any
                  ) -> ControllerDesign:
    fhocp = law.fhocp
    return ControllerDesign.common(fhocp, observer, 0.3, law.certified, model, u_lo, u_hi,
                                   fhocp.reference, "steady", {})


def title(law: Any) -> str:
    return "steady-state law"


def parameters(design: ControllerDesign, inputs: Any, outputs: Any) -> list[Any]:
    return []


def parameter_count(design: ControllerDesign) -> int:
    return 0


def c_switches(design: ControllerDesign) -> str:
    return ""
