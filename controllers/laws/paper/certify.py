"""The paper's law's hypotheses for ``cosim certify``: the certificate's own
(``th:feasibility-stability``: δISS, the observer, Assumption 1 and
``eq:condition-recursive-feasibility`` at each set-point), with a verdict and what would
fix each one that fails (:func:`controllers.certification.diagnosis.diagnose`)."""

from __future__ import annotations

from typing import Any

from controllers.laws.base import Certified

__all__ = ["certify"]


def certify(model: Any, cert: Any, kwargs: dict[str, Any], setpoints: list[Any],
            failures: list[str], n_design: int, no_theta: str | None) -> Certified:
    """The verdict on ``model`` and its certificate ``cert`` (with the observer gains
    certified; ``kwargs``: the design's arguments) at ``setpoints`` (normalised):
    ``failures`` are the certificate's failed hypotheses in words (the first ``n_design``
    the design's), ``no_theta`` why no observer-gain scale passes (``None``: one does); each
    failure is printed."""
    from controllers.certification import certificates as certs
    from controllers.certification.diagnosis import diagnose

    design = [m for m in failures[:n_design] if not m.startswith("δISS")]
    design += [no_theta] if no_theta else []

    def rhs_at(w: float) -> Any:
        return certs.compute_certificate(model, L_z=cert.L_z, L_r=cert.L_r, **{
            **kwargs, "w_y_bar": w}).admissible_box()

    verdict = diagnose(model, cert, "paper", setpoints, cert.admissible_box(), design, rhs_at)
    return Certified(verdict, lines=[f"FAILED: {msg}" for msg in failures])
