"""The tracking law in C: the numbers of its step (``law.c``), its tunable parameters and its
switches (:mod:`controllers.kernel.controller_source` joins them; docs:
guide/controller-fmu.md)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.kernel.controller_source import ControllerDesign

__all__ = ["c_switches", "export_design", "parameter_count", "parameters", "title"]


def export_design(law: Any, observer: Any, model: Any, u_lo: np.ndarray,
                  u_hi: np.ndarray) -> ControllerDesign:
    """The design of the tracking law ``law`` (its FHOCP with the artificial steady state,
    :class:`controllers.laws.tracking.reference.ArtificialSteadyState`, set up on its
    compiled kernel's SQP), its observer (:class:`controllers.observer.GRUObserver`), the
    model's normalisation and the input box. The law's numbers: ``Y_s``'s right-hand side
    on ``L U_o x_s`` (``CT_YS_BASE``), the terminal radius (``CT_ALPHA_C``), ``u_s``'s move
    limit per step (``CT_US_RATE``, −1: none) and the steady state's check tolerance
    (``CT_XS_CHECK_TOL``)."""
    from controllers.laws.tracking.reference import XS_CHECK_TOL

    fhocp = law.fhocp
    ass = fhocp.reference   # the artificial steady state
    law_data = {"CT_YS_BASE": np.asarray(ass.ys_base, float),
                "CT_ALPHA_C": float(ass.alpha_c),
                "CT_US_RATE": -1.0 if ass.us_rate is None else float(ass.us_rate),
                "CT_XS_CHECK_TOL": float(XS_CHECK_TOL)}
    return ControllerDesign.common(fhocp, observer, law.disturbance.beta, law.certified, model,
                                   u_lo, u_hi, ass, "tracking", law_data,
                                   output_limits=law.output_limits)


def title(law: Any) -> str:
    """How the FMU's description names the law."""
    return "tracking law"


def parameters(design: ControllerDesign, inputs: Any, outputs: Any
               ) -> list[tuple[str, float, float, str, float]]:
    """Its tunable parameters, in ``law.c``'s order (``LAW_P_*``): the law's settings
    (:func:`controllers.laws.tracking.law.settings_of`) at the design's values."""
    from controllers.laws.tracking.law import settings_of

    k = design.kernel
    return settings_of(design.beta, np.asarray(k.R, dtype=float),
                       np.asarray(k.du_weight, dtype=float) if k.has_du else None,
                       np.asarray(k.offset_weight, dtype=float), list(inputs), list(outputs))


def parameter_count(design: ControllerDesign) -> int:
    """``LAW_N_PARAMETERS`` of ``law.c`` for ``design``."""
    k = design.kernel
    m, p = np.shape(k.params["W_z"])[1], np.shape(k.params["U_o"])[0]
    return 1 + m + (m if k.has_du else 0) + p


def c_switches(design: ControllerDesign) -> str:
    """Its ``#define`` lines (none); refuses a design on another law's kernel."""
    if design.kernel.offset_weight is None:
        raise ValueError("the tracking law's design on another law's kernel")
    return ""
