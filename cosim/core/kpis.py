"""Key performance indicators of a closed-loop run (``summary.json``), keyed by the control
problem's signals.

Every per-signal KPI is ``kpis.<kpi>.<signal>`` in a run's ``summary.json``
(``kpis.iae.h1``, ``kpis.tv.qa``, ``kpis.violations.h1.max``) and the column
``<kpi>.<signal>`` of a campaign's ``runs.parquet`` (``iae.h1``, ``tv.qa``,
``violations.h1.max``): the column name is the path below ``kpis`` (:data:`PER_OUTPUT`,
:data:`PER_INPUT`, :data:`VIOLATION_FIELDS`; :func:`flat`). Nothing here knows a plant: the
outputs, inputs and boxes come from the run.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PER_INPUT", "PER_OUTPUT", "SETTLE_ROWS", "VIOLATION_FIELDS", "compute", "flat",
           "setpoint_errors", "summed"]

#: Rows at the end of a set-point interval over which the static offset is averaged.
SETTLE_ROWS = 20
#: Per-output KPIs: ``kpis.<kpi>.<output>`` (a number or ``None``).
PER_OUTPUT = ("iae", "final_error", "worst_offset")
#: Per-input KPIs: ``kpis.<kpi>.<input>``.
PER_INPUT = ("tv",)
#: The fields of ``kpis.violations.<signal>`` (per constrained output and input).
VIOLATION_FIELDS = ("max", "count")


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
        As recorded by :class:`cosim.core.master.Master` (``time``, ``ref.<o>``, ``plant.<o>``,
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
        Per output with a set-point: ``iae`` (∫|ref − y| dt, zero-order hold), ``final_error``
        (ref − y at the last row), ``worst_offset`` (the largest absolute static offset over the
        set-point intervals, see :func:`setpoint_errors`). Per constrained output and input:
        ``violations`` (``max``: largest amount outside the bounds, ``count``: rows outside).
        Per input: ``tv`` (total variation Σ|Δu|), ``control_effort`` (``integral_square``
        ∫u² dt, ``total_variation`` = ``tv``). ``setpoints``: one entry per interval of
        constant set-points. Units: the signals' own (IAE: output unit × s). Rows without a
        value (NaN: a live plant's sample with nothing measured) add nothing to the sums.
    """
    kpis: dict = {"iae": {}, "final_error": {}, "worst_offset": {}, "violations": {},
                  "tv": {}, "control_effort": {}, "setpoints": []}
    if not rows:
        return kpis
    data = np.asarray(rows, dtype=float)
    t = data[:, 0]
    dt = np.diff(t)
    for o in references:
        y, r = _col(columns, data, f"plant.{o}"), _col(columns, data, f"ref.{o}")
        if y is None or r is None:
            continue
        err = np.abs(r - y)   # NaN where nothing was measured (a live plant's Bad value)
        kpis["iae"][o] = float(np.nansum(err[:-1] * dt)) if len(t) > 1 else 0.0
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
        isq = float(np.nansum(v[:-1] ** 2 * dt)) if len(t) > 1 else 0.0
        tv = float(np.nansum(np.abs(np.diff(v))))
        kpis["tv"][u] = tv
        kpis["control_effort"][u] = {"integral_square": isq, "total_variation": tv}
    kpis["setpoints"] = setpoint_errors(columns, data, references)
    for o in kpis["iae"]:
        offsets = [abs(seg["offset"][o]) for seg in kpis["setpoints"]
                   if math.isfinite(seg["offset"].get(o, math.nan))]
        kpis["worst_offset"][o] = max(offsets, default=math.nan)
    return _finite(kpis)


def summed(summary: dict, kpi: str) -> float:
    """A run's ``kpi`` summed over its signals, each divided by its box width: ``"iae"`` over
    the outputs, ``"tv"`` over the inputs, from ``summary`` (``kpis`` and ``signals`` of a
    ``summary.json``): one number for a plant of any size, in units of its boxes."""
    kind = "inputs" if kpi in PER_INPUT else "outputs"
    boxes = summary["signals"][kind]
    return float(sum(v / (boxes[s]["max"] - boxes[s]["min"])
                     for s, v in summary["kpis"][kpi].items()))


def flat(kpis: dict) -> dict[str, float]:
    """The per-signal KPIs of :func:`compute` as ``{"<kpi>.<signal>": value}``.

    ``iae.<o>``, ``final_error.<o>``, ``worst_offset.<o>``, ``tv.<u>``,
    ``violations.<s>.max`` and ``violations.<s>.count``, in the order of the signals
    (outputs' KPIs first, then the inputs', then the violations); ``None`` becomes NaN. A
    ``summary.json`` written before ``worst_offset`` and ``tv`` existed gives them from
    ``setpoints`` and ``control_effort``.
    """
    out: dict[str, float] = {}
    kpis = kpis or {}
    worst = dict(kpis.get("worst_offset") or {})
    for o in kpis.get("iae") or {}:
        if o not in worst:  # an older summary.json
            offsets = [abs(v) for seg in kpis.get("setpoints") or []
                       if (v := (seg.get("offset") or {}).get(o)) is not None]
            worst[o] = max(offsets, default=None)
    per_output = {"iae": kpis.get("iae") or {}, "final_error": kpis.get("final_error") or {},
                  "worst_offset": worst}
    for name, values in per_output.items():
        for o, v in values.items():
            out[f"{name}.{o}"] = _number(v)
    tv = kpis.get("tv")
    if tv is None:  # an older summary.json
        tv = {u: e.get("total_variation") for u, e in (kpis.get("control_effort") or {}).items()}
    for u, v in tv.items():
        out[f"tv.{u}"] = _number(v)
    for s, v in (kpis.get("violations") or {}).items():
        for field in VIOLATION_FIELDS:
            out[f"violations.{s}.{field}"] = _number((v or {}).get(field))
    return out


def _number(value: object) -> float:
    return math.nan if value is None else float(value)  # type: ignore[arg-type]


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
