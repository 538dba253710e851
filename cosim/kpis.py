"""Key performance indicators of a closed-loop run (``summary.json``)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SETTLE_ROWS", "compute", "setpoint_errors"]

#: Rows at the end of a set-point interval over which the static offset is averaged.
SETTLE_ROWS = 20


def _col(columns: list[str], data: np.ndarray, name: str) -> np.ndarray | None:
    try:
        return data[:, columns.index(name)]
    except ValueError:
        return None


def compute(columns: list[str], rows: list[list[float]], outputs: list[str],
            references: list[str], inputs: list[str],
            bounds: dict[str, tuple[float, float]]) -> dict:
    """KPIs from recorded rows (values held over each communication interval).

    Parameters
    ----------
    columns, rows
        As recorded by :class:`cosim.master.Master` (``time``, ``ref.<o>``, ``plant.<o>``,
        ``ctrl.<u>``, ...).
    outputs : list of str
        Controlled/measured outputs (``plant.<o>`` is the true plant value).
    references : list of str
        Outputs with a set-point ``ref.<o>``.
    inputs : list of str
        Manipulated inputs ``ctrl.<u>``.
    bounds : dict
        ``(min, max)`` by signal name.

    Returns
    -------
    dict
        ``iae`` (∫|ref − y| dt per output, zero-order hold), ``final_error`` (ref − y at the
        last row), ``violations`` per constrained output and input (``max``: largest amount
        outside the bounds, ``count``: rows outside), ``control_effort`` per input
        (``integral_square`` ∫u² dt, ``total_variation`` Σ|Δu|), ``setpoints``: one entry
        per interval of constant set-points (see :func:`setpoint_errors`).
    """
    kpis: dict = {"iae": {}, "final_error": {}, "violations": {}, "control_effort": {},
                  "setpoints": []}
    if not rows:
        return kpis
    data = np.asarray(rows, dtype=float)
    t = data[:, 0]
    dt = np.diff(t)
    for o in references:
        y, r = _col(columns, data, f"plant.{o}"), _col(columns, data, f"ref.{o}")
        if y is None or r is None:
            continue
        err = np.abs(r - y)
        kpis["iae"][o] = float(np.sum(err[:-1] * dt)) if len(t) > 1 else 0.0
        kpis["final_error"][o] = float(r[-1] - y[-1])
    for name, (lo, hi) in bounds.items():
        v = _col(columns, data, f"plant.{name}")
        if v is None:
            v = _col(columns, data, f"ctrl.{name}")
        if v is None:
            continue
        excess = np.maximum(np.maximum(lo - v, v - hi), 0.0)
        excess = np.nan_to_num(excess, nan=0.0)
        kpis["violations"][name] = {"max": float(excess.max()),
                                    "count": int(np.count_nonzero(excess > 0.0))}
    for u in inputs:
        v = _col(columns, data, f"ctrl.{u}")
        if v is None:
            continue
        isq = float(np.sum(v[:-1] ** 2 * dt)) if len(t) > 1 else 0.0
        tv = float(np.sum(np.abs(np.diff(v))))
        kpis["control_effort"][u] = {"integral_square": isq, "total_variation": tv}
    kpis["setpoints"] = setpoint_errors(columns, data, references)
    return _finite(kpis)


def setpoint_errors(columns: list[str], data: np.ndarray, references: list[str],
                    settle_rows: int = SETTLE_ROWS) -> list[dict]:
    """Tracking error at each set-point: the static offset the paper reports.

    For each interval over which every ``ref.<o>`` is constant: ``start``/``end`` times,
    the set-points ``ref``, and ``offset`` = mean of ``y − ref`` over the interval's last
    ``settle_rows`` rows (or its second half when shorter), per output.
    """
    refs = [(o, _col(columns, data, f"ref.{o}"), _col(columns, data, f"plant.{o}"))
            for o in references]
    refs = [(o, r, y) for o, r, y in refs if r is not None and y is not None]
    if not refs or len(data) == 0:
        return []
    t = data[:, 0]
    ref_matrix = np.column_stack([r for _, r, _ in refs])
    changes = np.flatnonzero(np.any(np.diff(ref_matrix, axis=0) != 0.0, axis=1)) + 1
    starts = [0, *changes.tolist()]
    ends = [*changes.tolist(), len(t)]
    segments = []
    for i0, i1 in zip(starts, ends, strict=True):
        tail = slice(max(i0 + (i1 - i0) // 2, i1 - settle_rows), i1)
        segments.append({
            "start": float(t[i0]),
            "end": float(t[i1 - 1]),
            "ref": {o: float(r[i0]) for o, r, _ in refs},
            "offset": {o: float(np.mean(y[tail] - r[tail])) for o, r, y in refs},
        })
    return segments


def _finite(obj: object) -> object:
    """Replace non-finite floats by None (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
