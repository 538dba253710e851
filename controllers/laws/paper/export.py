"""The paper's law in C: the numbers of its step (``law.c`` and ``governor.c``), its tunable
parameters and its switches (:mod:`controllers.kernel.controller_source` joins them; docs:
guide/controller-fmu.md)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.kernel.controller_source import ControllerDesign

__all__ = ["c_switches", "export_design", "parameter_count", "parameters", "title"]


def export_design(law: Any, observer: Any, model: Any, u_lo: np.ndarray,
                  u_hi: np.ndarray) -> ControllerDesign:
    """The design of the paper's law (:class:`controllers.laws.paper.law.PaperLaw`, its FHOCP
    on its compiled kernel's SQP) with its observer, the model's normalisation and the input
    box. The law's numbers: the certificate's set-point checks (``Certificate.ok``,
    ``alpha``: its ``L``, ``h``, ``ẽ_o a_N``, ``b_N``, ``w_L``, ``c_s``, the two sides of
    ``eq:condition-recursive-feasibility`` and whether the design conditions hold), the
    admissible range per output (``Certificate.admissible_bounds``), the set-point rate (−1:
    none) and the reference governor's (:class:`controllers.laws.paper.governor.
    ReferenceGovernor`: whether it runs, its levels, ``λ_max``'s floor and growth, the
    Newton's cap and tolerance)."""
    from controllers.equilibrium import EQ_TOL, NEWTON_MAX_ITER
    from controllers.laws.paper.governor import LAM_GROW, LAM_MIN

    cert, h, gov = law.cert, law.handling, law.governor
    lo, hi = cert.admissible_bounds()
    # Certificate.ok's design conditions (the uncertified design's: a finite terminal weight,
    # not nu < 1) and what eq:condition-recursive-feasibility needs to be evaluated at all
    design_ok = (not cert.failures() and cert.rho_s < 1 and bool(np.isfinite(cert.e_tilde)))
    # (recursive_feasibility: ρ_s^N (L_max ẽ_o + w̄) ≤ α (1 − ρ_s); never read without
    # design_ok)
    rf_lhs = (cert.rho_s ** cert.N * (cert.L_max * cert.e_tilde + cert.w_bar)
              if design_ok else 0.0)
    law_data = {"CT_CERT_L": np.asarray(cert.L, float), "CT_CERT_H": np.asarray(cert.h, float),
                "CT_CERT_EAN": np.asarray(cert.e_tilde * cert.a[cert.N], float),
                "CT_CERT_BN": np.asarray(cert.b[cert.N], float),
                "CT_CERT_WL": np.asarray(cert.w_L, float),
                "CT_CERT_CS": np.asarray(cert.c_s, float),
                "CT_CERT_RF_LHS": float(rf_lhs),
                "CT_CERT_RF_ONE_MINUS_RHO": float(1 - cert.rho_s),
                "CT_CERT_DESIGN_OK": int(design_ok), "CT_BOX_LO": lo, "CT_BOX_HI": hi,
                "CT_SETPOINT_RATE": -1.0 if h.setpoint_rate is None else float(h.setpoint_rate),
                "CT_GOVERNOR": int(gov is not None),
                "CT_GOV_LEVELS": int(gov.levels if gov is not None else 0),
                "CT_GOV_LAM_MIN": float(LAM_MIN), "CT_GOV_LAM_GROW": float(LAM_GROW),
                "CT_EQ_NEWTON_MAX_ITER": int(NEWTON_MAX_ITER),
                "CT_EQ_NEWTON_TOL": float(EQ_TOL)}
    fhocp = law.fhocp
    return ControllerDesign.common(fhocp, observer, h.offset_filter, law.certified, model, u_lo,
                                   u_hi, fhocp.reference.layout, "paper", law_data,
                                   offset_free=bool(h.offset_free))


def title(law: Any) -> str:
    """How the FMU's description names the law."""
    return "paper's law" + (", offset-free" if law.handling.offset_free else "")


def _rate_tunable(design: ControllerDesign) -> bool:
    """Designed with a set-point rate (``CT_RATE_TUNABLE``)."""
    return float(design.law_data["CT_SETPOINT_RATE"]) >= 0.0


def parameters(design: ControllerDesign, inputs: Any, outputs: Any
               ) -> list[tuple[str, float, float, str, float]]:
    """Its tunable parameters, in ``law.c``'s order (``LAW_P_*``): the law's settings
    (:func:`controllers.laws.paper.law.settings_of`) at the design's values."""
    from controllers.laws.paper.law import settings_of

    k = design.kernel
    return settings_of(float(design.beta) if design.offset_free else None,
                       np.asarray(k.R, dtype=float),
                       np.asarray(k.du_weight, dtype=float) if k.has_du else None,
                       float(design.law_data["CT_SETPOINT_RATE"]) if _rate_tunable(design)
                       else None, list(inputs))


def parameter_count(design: ControllerDesign) -> int:
    """``LAW_N_PARAMETERS`` of ``law.c`` for ``design``."""
    k = design.kernel
    m = np.shape(k.params["W_z"])[1]
    return (int(design.offset_free) + m + (m if k.has_du else 0)
            + int(_rate_tunable(design)))


def c_switches(design: ControllerDesign) -> str:
    """Its ``#define`` lines: ``offset_free`` and whether the set-point rate is tunable
    decide the step's parameters; refuses a design on another law's kernel."""
    if design.kernel.offset_weight is not None:
        raise ValueError("the paper law's design on another law's kernel")
    return (f"#define CT_OFFSET_FREE {int(design.offset_free)}\n"
            f"#define CT_RATE_TUNABLE {int(_rate_tunable(design))}\n")
