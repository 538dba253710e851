"""The outputs a certificate admits, as intervals per output (``ass:setpoint`` and
``eq:condition-recursive-feasibility``): the box rows of ``L y ≤ rhs`` read as bounds, in the
model's normalised units (:func:`box_bounds`) and the user's (:func:`box_ranges`,
:func:`admissible_ranges`), for ``cosim certify``'s report, campaigns' set-point draws and
the diagnosis of a failed design.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from controllers.certification.certificates import Certificate

__all__ = ["admissible_ranges", "box_bounds", "box_ranges"]


def box_bounds(L: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``{y : L y ≤ rhs}`` of the box rows of ``L`` (one nonzero entry) as bounds per output,
    ``(lo, hi)`` (normalised): ±∞ where no row bounds an output, NaN where a bound is NaN."""
    p = np.shape(L)[1]
    lo, hi = np.full(p, -np.inf), np.full(p, np.inf)
    for j in range(p):
        for row, r in zip(L, rhs, strict=True):
            if row[j] == 0 or np.count_nonzero(row) != 1:
                continue
            bound = float(r / row[j])
            if math.isnan(bound):
                lo[j] = hi[j] = math.nan
                break
            if row[j] > 0:
                hi[j] = min(hi[j], bound)
            else:
                lo[j] = max(lo[j], bound)
    return lo, hi


def box_ranges(model: Any, L: np.ndarray, rhs: np.ndarray
               ) -> list[tuple[str, float | None, float | None]]:
    """:func:`box_bounds` as an interval ``(name, lo, hi)`` per output, physical units;
    ``(name, None, None)`` where it is empty or undefined (a NaN bound)."""
    out: list[tuple[str, float | None, float | None]] = []
    for j, (lo, hi) in enumerate(zip(*box_bounds(L, rhs), strict=True)):
        name = model.output_names[j]
        a, b = sorted((float(lo * model.y_scale[j] + model.y_offset[j]),
                       float(hi * model.y_scale[j] + model.y_offset[j])))
        out.append((name, a, b) if lo <= hi else (name, None, None))
    return out


def admissible_ranges(cert: Certificate,
                      model: Any) -> list[tuple[str, float | None, float | None]]:
    """Per-output admissible set-point interval ``(name, lo, hi)`` in physical units.

    :func:`box_ranges` of :meth:`Certificate.admissible_box` (``ass:setpoint`` and
    ``eq:condition-recursive-feasibility``); ``(name, None, None)`` when it is empty (or
    undefined: a NaN bound). Whether the model reaches a set-point (``‖ū‖∞ ≤ 1``) is not part of
    it: :meth:`Certificate.reference` decides that.
    """
    return box_ranges(model, cert.L, cert.admissible_box())
