"""The toy law's hypotheses for ``cosim certify``: the design's certificate (the paper's)."""

from __future__ import annotations

from typing import Any

from controllers.laws.base import Certified


def certify(model: Any, cert: Any, kwargs: dict[str, Any], setpoints: list[Any],
            failures: list[str], n_design: int, no_theta: str | None) -> Certified:
    from controllers.laws.paper.certify import certify as paper

    verdict = paper(model, cert, kwargs, setpoints, failures, n_design, no_theta).verdict
    return Certified(verdict, {"steady": True}, ["steady-state law: the design's certificate"])
