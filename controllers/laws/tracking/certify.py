"""The tracking law's hypotheses for ``cosim certify``: its design at zero observer gains
(:mod:`controllers.laws.tracking.checks`: the weights, ``α_c`` against
``eq:condition-recursive-feasibility``, ``Y_s`` not empty, the steady-state gain on a grid)
with the robust MPC's defaults, a verdict and what would fix each one that fails."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.laws.base import Certified

__all__ = ["certify"]


def certify(model: Any, cert: Any, kwargs: dict[str, Any], setpoints: list[Any],
            failures: list[str], n_design: int, no_theta: str | None) -> Certified:
    """The verdict on ``model`` under the tracking law at ``setpoints`` (normalised), its
    hypotheses (the JSON document's ``tracking``) and their line. ``cert``: the design's
    certificate with the observer gains, whose ``α_min(N)`` is the default ``α_c`` when its
    gain scale passed (``no_theta`` is ``None``), else :func:`controllers.laws.tracking.law.
    fallback_alpha_c`."""
    from controllers.certification import certificates as certs
    from controllers.certification.diagnosis import diagnose
    from controllers.laws.tracking import SPEC
    from controllers.laws.tracking.checks import failures as failed
    from controllers.laws.tracking.checks import tracking_hypotheses
    from controllers.laws.tracking.law import fallback_alpha_c
    from controllers.laws.tracking.reference import ArtificialSteadyState, steady_output_bounds
    from controllers.ocp.fhocp import FHOCP

    cert_t = certs.compute_certificate(model, gain_scale=0.0, **kwargs)
    if not cert_t.nu < 1:     # no δISS: no tracking design to check
        return Certified(diagnose(model, cert_t, "tracking", setpoints,
                                  np.full(cert_t.h.shape, -np.inf), [], None),
                         {"tracking": {}})
    gains = no_theta is None and not cert.failures()
    alpha_c = cert.alpha_min() if gains else math.nan
    if not (math.isfinite(alpha_c) and alpha_c > 0):
        alpha_c = fallback_alpha_c(cert_t)
    reference = ArtificialSteadyState(SPEC.option("offset_weight").default, alpha_c)
    fh = FHOCP.from_certificate(cert_t, reference=reference,
                                du_weight=SPEC.defaults["du_weight"])
    h = tracking_hypotheses(fh, cert_t, SPEC.defaults["offset_filter"])

    def rhs_at(w: float) -> Any:
        return steady_output_bounds(certs.compute_certificate(
            model, gain_scale=0.0, **{**kwargs, "w_y_bar": w}), alpha_c)

    design = [msg for msg in failed(h) if not msg.startswith("no admissible steady")]
    verdict = diagnose(model, cert_t, "tracking", setpoints, fh.reference.ys_bounds, design,
                       rhs_at)
    return Certified(verdict, {"tracking": h}, [_line(h)])


def _line(h: dict[str, Any]) -> str:
    """The tracking law's hypotheses in one line."""
    def fmt(v: Any) -> str:
        return ("yes" if v else "NO") if isinstance(v, bool) else f"{float(v):.6g}"

    sv = h["steady_gain_min_singular_value"]
    return (f"tracking law (zero observer gains): alpha_c = {h['alpha_c']:.6g}, alpha_min = "
            f"{h['alpha_min']:.6g}, eq:condition-recursive-feasibility = "
            f"{fmt(h['recursive_feasibility'])}; Y_s not empty = {fmt(h['Ys_nonempty'])}; "
            f"admissible steady states on the input grid: {h['grid_points_admissible']} of "
            f"{h['grid_points']}, smallest singular value of the steady-state gain there: "
            + ("none" if sv is None else f"{sv:.4g}"))
