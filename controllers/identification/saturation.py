"""Outputs whose sensor saturates: finding the limits in a record, and what they mean.

A level sensor at the top of its range, a thermocouple amplifier at its rail: a logged output
that sits at one value for many samples, that value its largest (or smallest), is a sensor
limit, not the plant's output. Fitting a model to the plateau teaches it a flat top the plant
does not have. Identification therefore treats a sample at a limit as "the output is at or
beyond this value": a prediction beyond the limit is no error
(:mod:`controllers.identification.sim_loss`), and the model's simulated output is read through
the same sensor (clipped to the limits) when it is scored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_SAMPLES", "MIN_SHARE", "SensorLimits", "detect", "flags"]

#: A value is a sensor limit when the record's largest (smallest) value of an output is taken
#: by at least this many samples and this share of the rows...
MIN_SAMPLES = 10
MIN_SHARE = 0.005
#: ... within this share of the output's range in the rows (a sensor at its rail may still
#: read a few LSBs apart; a peak of the plant's own is taken by a handful of samples).
TOLERANCE = 1e-3


@dataclass(frozen=True)
class SensorLimits:
    """Per output: the lower and upper sensor limits found (``None``: none), normalised."""

    lower: tuple[float | None, ...]
    upper: tuple[float | None, ...]
    #: per output, the width of the band read as "at the limit" (normalised)
    band: tuple[float, ...] = ()

    @property
    def any(self) -> bool:
        """Whether some output has a limit."""
        return any(v is not None for v in (*self.lower, *self.upper))

    def clip(self, xi: np.ndarray) -> np.ndarray:
        """``xi`` (…, p) read through the sensor: clipped to the limits."""
        out = np.array(xi, dtype=float, copy=True)
        for j, (lo, hi) in enumerate(zip(self.lower, self.upper, strict=True)):
            if lo is not None:
                out[..., j] = np.maximum(out[..., j], lo)
            if hi is not None:
                out[..., j] = np.minimum(out[..., j], hi)
        return out

    def to_dict(self, names: list[str], scale: np.ndarray, offset: np.ndarray) -> dict:
        """``{output: {"lower": value, "upper": value}}`` in physical units (only the limits
        found)."""
        out: dict[str, dict[str, float]] = {}
        for j, name in enumerate(names):
            for key, v in (("lower", self.lower[j]), ("upper", self.upper[j])):
                if v is not None:
                    phys = float(v * scale[j] + offset[j])
                    out.setdefault(name, {})[key] = phys
        return out


def detect(y: np.ndarray, rows: np.ndarray | None = None) -> SensorLimits:
    """The sensor limits of each output of ``y`` (T, p) (normalised), from the rows ``rows``
    (a boolean mask; default all): an output's largest value is an upper limit when at least
    :data:`MIN_SAMPLES` samples and :data:`MIN_SHARE` of the rows lie within
    :data:`TOLERANCE` of its range from it (the smallest likewise)."""
    y = np.asarray(y, dtype=float)
    sel = y if rows is None else y[np.asarray(rows, dtype=bool)]
    count = max(MIN_SAMPLES, int(np.ceil(MIN_SHARE * len(sel))))
    lower: list[float | None] = []
    upper: list[float | None] = []
    band: list[float] = []
    for j in range(y.shape[1]):
        col = sel[:, j]
        if col.size == 0 or np.max(col) == np.min(col):
            lower.append(None)
            upper.append(None)
            band.append(0.0)
            continue
        hi, lo = float(np.max(col)), float(np.min(col))
        tol = TOLERANCE * (hi - lo)
        upper.append(hi if np.count_nonzero(col >= hi - tol) >= count else None)
        lower.append(lo if np.count_nonzero(col <= lo + tol) >= count else None)
        band.append(tol)
    return SensorLimits(tuple(lower), tuple(upper), tuple(band))


def flags(y: np.ndarray, limits: SensorLimits) -> np.ndarray:
    """Per sample and output (int8): +1 at the upper limit, −1 at the lower one, else 0."""
    y = np.asarray(y, dtype=float)
    out = np.zeros(y.shape, dtype=np.int8)
    for j, (lo, hi) in enumerate(zip(limits.lower, limits.upper, strict=True)):
        tol = limits.band[j] if j < len(limits.band) else 0.0
        if hi is not None:
            out[..., j][y[..., j] >= hi - tol] = 1
        if lo is not None:
            out[..., j][y[..., j] <= lo + tol] = -1
    return out
