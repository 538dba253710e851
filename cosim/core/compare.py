"""Compare a result CSV with a reference CSV inside a tolerance band.

Used by ``cosim compare`` and by the regression suite (``tests/regression``) so that a change
of model, solver or FMU never silently changes closed-loop behaviour.

Files
-----
Both files follow the cross-check CSV conventions of ``results.csv``: a header row, the time
[s] in the first column (whatever its name), one column per signal, comma separated, names
may be quoted, rows in strictly increasing time. Signals are matched by column name.

Common times
------------
Both signals are compared on the *union* of the two time grids. A time that only one file
covers (one run stopped early, or ran longer) counts as a point outside the band. Between
samples a signal is interpolated *piecewise-linearly*; at a sample time its value is taken
exactly (no arithmetic), so files on the same grid are compared value by value.

Tolerance band
--------------
* pointwise (default): a point passes when ``|r − ref| ≤ atol + rtol·|ref|``.
* ``band=True`` (the FMI cross-check style): at each common time ``t`` the band is the
  minimum/maximum of the reference over ``[t − window, t + window]`` (default window: one
  reference sample, the median spacing of the reference times), widened on both sides by
  ``atol + rtol·range`` where ``range`` is max − min of the reference over the whole file. This
  tolerates small time shifts of steps and events.

Two NaNs (or two equal infinities) at the same point agree; a NaN against a number does not.

The files are read by :func:`cosim.core.csvio.read_table` (re-exported here with
:class:`~cosim.core.csvio.Table`); the figure of ``cosim compare --plot`` is
:func:`cosim.core.plots.compare_figure`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.core.csvio import Table, read_table
from cosim.core.errors import CosimError

__all__ = [
    "DEFAULT_ATOL",
    "DEFAULT_RTOL",
    "Comparison",
    "SignalComparison",
    "Table",
    "Tolerance",
    "compare",
    "compare_tables",
    "format_report",
    "read_table",
    "resample",
    "window_extrema",
]

#: Default relative tolerance: tight enough that a small change of tuning or model fails.
DEFAULT_RTOL = 1e-4
#: Default absolute tolerance, in each signal's own unit (the control problem's; SI for the
#: four tanks): signals are compared by column name, whatever the plant.
DEFAULT_ATOL = 1e-9

Tolerance = float | Mapping[str, float]


# --------------------------------------------------------------------------------------------
# Resampling and tolerance bands
# --------------------------------------------------------------------------------------------

def resample(t: np.ndarray, y: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of ``(t, y)`` at times ``at`` inside ``[t[0], t[-1]]``.

    A time equal to a sample time returns that sample exactly (also when a neighbour is NaN);
    times outside the span give NaN. ``t`` must be strictly increasing.
    """
    at = np.asarray(at, dtype=float)
    out = np.full(at.shape, np.nan)
    inside = (at >= t[0]) & (at <= t[-1])
    idx = np.searchsorted(t, at[inside], side="left")
    idx = np.minimum(idx, len(t) - 1)
    exact = t[idx] == at[inside]
    vals = np.empty(idx.shape)
    vals[exact] = y[idx[exact]]
    k = idx[~exact]  # t[k-1] < at < t[k], k >= 1
    if k.size:
        x = at[inside][~exact]
        w = (x - t[k - 1]) / (t[k] - t[k - 1])
        with np.errstate(invalid="ignore"):
            vals[~exact] = (1.0 - w) * y[k - 1] + w * y[k]
    out[inside] = vals
    return out


def window_extrema(t: np.ndarray, y: np.ndarray, at: np.ndarray,
                   window: float) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of the piecewise-linear ``(t, y)`` over ``[a − window, a + window]``.

    The window is clipped to ``[t[0], t[-1]]``; NaN samples are ignored (a window holding only
    NaNs gives NaN). The extrema of a piecewise-linear signal lie at its samples or at the
    window ends, so only those are examined.
    """
    lo = np.full(at.shape, np.nan)
    hi = np.full(at.shape, np.nan)
    starts = np.maximum(at - window, t[0])
    ends = np.minimum(at + window, t[-1])
    i0 = np.searchsorted(t, starts, side="left")
    i1 = np.searchsorted(t, ends, side="right")
    y_start = resample(t, y, starts)
    y_end = resample(t, y, ends)
    for n in range(at.size):
        if starts[n] > ends[n]:
            continue  # the time lies outside the reference span
        vals = np.concatenate((y[i0[n]:i1[n]], [y_start[n], y_end[n]]))
        vals = vals[~np.isnan(vals)]
        if vals.size:
            lo[n] = vals.min()
            hi[n] = vals.max()
    return lo, hi


def _check_tolerance_names(label: str, value: Tolerance, signals: Sequence[str]) -> None:
    """A per-signal tolerance must name a compared signal (``"*"`` is the default)."""
    if not isinstance(value, Mapping):
        return
    for name in value:
        if name == "*" or name in signals:
            continue
        close = [s for s in signals if s.rpartition(".")[2] == name]
        hint = ("; did you mean " + " or ".join(f"'{c}'" for c in close) + "?") if close else ""
        raise CosimError(f"--{label} {name}={value[name]:g}: '{name}' is not a compared signal "
                         f"(compared: {_names(list(signals))}){hint}")


def _tol(value: Tolerance, name: str, default: float) -> float:
    if isinstance(value, Mapping):
        return float(value.get(name, value.get("*", default)))
    return float(value)


# --------------------------------------------------------------------------------------------
# Comparison
# --------------------------------------------------------------------------------------------

@dataclass
class SignalComparison:
    """The verdict on one signal, with the arrays needed to plot it.

    Attributes
    ----------
    name : str
    rtol, atol : float
    time : ndarray
        Common times (union of both grids).
    result, reference : ndarray
        Both signals on :attr:`time` (NaN where a file does not cover the time).
    lower, upper : ndarray
        The tolerance band on :attr:`time`.
    outside : ndarray of bool
        Points outside the band (or covered by one file only).
    """

    name: str
    rtol: float
    atol: float
    time: np.ndarray
    result: np.ndarray
    reference: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    outside: np.ndarray
    missing: np.ndarray

    @property
    def passed(self) -> bool:
        return not bool(self.outside.any())

    @property
    def n_points(self) -> int:
        return int(self.time.size)

    @property
    def n_outside(self) -> int:
        return int(self.outside.sum())

    @property
    def deviation(self) -> np.ndarray:
        """``|result − reference|`` per point (0 where both agree, NaN where one is missing)."""
        with np.errstate(invalid="ignore"):
            d = np.abs(self.result - self.reference)
        same = (self.result == self.reference) | (np.isnan(self.result)
                                                  & np.isnan(self.reference) & ~self.missing)
        d[same] = 0.0
        d[np.isnan(d) & ~self.missing] = np.inf  # NaN against a number
        return d

    @property
    def max_deviation(self) -> tuple[float, float]:
        """Largest ``|result − reference|`` over the points both files cover, and its time."""
        d = np.where(self.missing, -1.0, self.deviation)
        if not (d >= 0).any():
            return math.nan, math.nan
        i = int(np.argmax(d))
        return float(d[i]), float(self.time[i])

    @property
    def excess(self) -> np.ndarray:
        """How far each point lies outside the band (≤ 0 inside; inf if missing or NaN)."""
        with np.errstate(invalid="ignore"):
            e = np.maximum(self.lower - self.result, self.result - self.upper)
        e[np.isnan(e)] = -np.inf
        e[self.outside & ~np.isfinite(e)] = np.inf
        return e

    @property
    def worst(self) -> int | None:
        """Index of the point furthest outside the band (None when all pass)."""
        if self.passed:
            return None
        e = np.where(self.outside, self.excess, -np.inf)
        return int(np.argmax(e))


@dataclass
class Comparison:
    """The outcome of :func:`compare`: one :class:`SignalComparison` per signal."""

    result_path: Path
    reference_path: Path
    band: bool
    window: float | None
    signals: list[SignalComparison]
    notes: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(s.passed for s in self.signals)

    @property
    def failed(self) -> list[SignalComparison]:
        return [s for s in self.signals if not s.passed]

    def report(self, quiet: bool = False) -> str:
        """A readable report: a table of signals, then the worst point of each failure.

        With ``quiet`` only the failures and the verdict line are given.
        """
        return format_report(self, quiet=quiet)


def _selected(result: Table, reference: Table, signals: Sequence[str] | None) -> list[str]:
    """The signals to compare: the given ones (each in both files), else every signal of
    the reference when both files have the same; a one-line error naming what is missing."""
    if signals is None:
        only_res = [n for n in result.names if n not in reference.names]
        only_ref = [n for n in reference.names if n not in result.names]
        if only_ref or only_res:
            parts = []
            if only_ref:
                parts.append(f"{result.path} lacks {_names(only_ref)} (in the reference)")
            if only_res:
                parts.append(f"{reference.path} lacks {_names(only_res)} (in the result)")
            common = [n for n in reference.names if n in result.names]
            hint = (f"; choose with --signals (common: {_names(common)})" if common
                    else "; the files have no signal in common")
            raise CosimError("; ".join(parts) + hint)
        return list(reference.names)
    chosen = list(dict.fromkeys(s.strip() for s in signals if s.strip()))
    if not chosen:
        raise CosimError("no signals selected")
    for where, table in (("result", result), ("reference", reference)):
        missing = [s for s in chosen if s not in table.names]
        if missing:
            raise CosimError(f"{table.path}: no signal {_names(missing)} in the {where} "
                             f"(it has {_names(table.names)})")
    return chosen


def compare_tables(result: Table, reference: Table, signals: Sequence[str] | None = None,
                   rtol: Tolerance = DEFAULT_RTOL, atol: Tolerance = DEFAULT_ATOL,
                   band: bool = False, window: float | None = None) -> Comparison:
    """Compare two parsed tables (see the module docstring for the semantics).

    Parameters
    ----------
    result, reference : Table
    signals : sequence of str, optional
        Signals to compare; default every signal column. Each must be in both files.
    rtol, atol : float or mapping
        Tolerances; a mapping gives per-signal values, with ``"*"`` as the default for the
        others (else :data:`DEFAULT_RTOL` / :data:`DEFAULT_ATOL`).
    band : bool
        Use the cross-check band (window min/max of the reference, widened by
        ``atol + rtol·range``) instead of the pointwise rule.
    window : float, optional
        Half-width of the band's window [s]; default one reference sample.

    Raises
    ------
    CosimError
        A signal missing in one file, no signals, a bad tolerance or window, a per-signal
        tolerance naming a signal that is not compared, or a cell that is not a number.
    """
    signals = _selected(result, reference, signals)
    for label, tol in (("rtol", rtol), ("atol", atol)):
        _check_tolerance_names(label, tol, signals)
    if window is not None and not (math.isfinite(window) and window >= 0):
        raise CosimError(f"window must be a finite number ≥ 0 s, got {window}")
    if band and window is None:
        window = float(np.median(np.diff(reference.time))) if reference.time.size > 1 else 0.0

    time = np.union1d(result.time, reference.time)
    notes = []
    for a, b, what in ((result, reference, "result"), (reference, result, "reference")):
        if a.time[0] > b.time[0] or a.time[-1] < b.time[-1]:
            notes.append(f"the {what} covers only t = {a.time[0]:g}..{a.time[-1]:g} s of "
                         f"{b.time[0]:g}..{b.time[-1]:g} s; uncovered times count as outside")
    missing = ((time < result.time[0]) | (time > result.time[-1])
               | (time < reference.time[0]) | (time > reference.time[-1]))

    out = []
    for name in signals:
        rt, at = _tol(rtol, name, DEFAULT_RTOL), _tol(atol, name, DEFAULT_ATOL)
        if not (math.isfinite(rt) and rt >= 0 and math.isfinite(at) and at >= 0):
            raise CosimError(f"signal '{name}': tolerances must be finite and ≥ 0 "
                             f"(rtol={rt:g}, atol={at:g})")
        r_raw, ref_raw = result.column(name), reference.column(name)
        r = resample(result.time, r_raw, time)
        ref = resample(reference.time, ref_raw, time)
        if band:
            lo, hi = window_extrema(reference.time, ref_raw, time, window)
            finite = ref_raw[np.isfinite(ref_raw)]
            span = float(finite.max() - finite.min()) if finite.size else 0.0
            widen = at + rt * span
            lo, hi = lo - widen, hi + widen
        else:
            with np.errstate(invalid="ignore"):
                tol = at + rt * np.abs(ref)
            lo, hi = ref - tol, ref + tol
        # A point passes when inside the band, or when it equals the reference exactly
        # (two NaNs, two equal infinities).
        with np.errstate(invalid="ignore"):
            inside = (r >= lo) & (r <= hi)
        same = (r == ref) | (np.isnan(r) & np.isnan(ref))
        outside = missing | ~(inside | same)
        out.append(SignalComparison(name, rt, at, time, r, ref, lo, hi, outside, missing))
    return Comparison(result.path, reference.path, band, window, out, notes)


def compare(result: str | Path, reference: str | Path, signals: Sequence[str] | None = None,
            rtol: Tolerance = DEFAULT_RTOL, atol: Tolerance = DEFAULT_ATOL,
            band: bool = False, window: float | None = None) -> Comparison:
    """Read two result CSVs and compare them; see :func:`compare_tables`."""
    return compare_tables(read_table(result), read_table(reference), signals=signals,
                          rtol=rtol, atol=atol, band=band, window=window)


def _names(names: Sequence[str], limit: int = 8) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------

def _g(x: float, digits: int = 4) -> str:
    return "-" if x is None or math.isnan(x) else f"{x:.{digits}g}"


def format_report(c: Comparison, quiet: bool = False) -> str:
    """The text report of a :class:`Comparison` (see :meth:`Comparison.report`)."""
    lines: list[str] = []
    if not quiet:
        if c.band:
            rule = (f"band: reference min/max over ±{c.window:g} s, widened by "
                    f"atol + rtol·range")
        else:
            rule = "pointwise: |result − reference| ≤ atol + rtol·|reference|"
        n = c.signals[0].n_points if c.signals else 0
        lines += [f"result:    {c.result_path}",
                  f"reference: {c.reference_path}",
                  f"rule:      {rule}",
                  f"times:     {n} (union of both time grids, piecewise-linear in between)"]
        lines += [f"note:      {note}" for note in c.notes]
        header = ("signal", "max |dev|", "at t [s]", "rtol", "atol", "outside", "verdict")
        rows = []
        for s in c.signals:
            dev, t_dev = s.max_deviation
            frac = s.n_outside / s.n_points if s.n_points else 0.0
            rows.append((s.name, _g(dev), _g(t_dev), f"{s.rtol:g}", f"{s.atol:g}",
                         f"{s.n_outside}/{s.n_points} ({100 * frac:.1f}%)",
                         "PASS" if s.passed else "FAIL"))
        widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
        fmt = "  ".join(f"{{:<{w}}}" if i == 0 else f"{{:>{w}}}"
                        for i, w in enumerate(widths))
        lines.append("")
        lines.append(fmt.format(*header).rstrip())
        lines.append("  ".join("-" * w for w in widths))
        lines += [fmt.format(*r) for r in rows]
    failed = c.failed
    if failed:
        if not quiet:
            lines.append("")
        for s in failed:
            i = s.worst
            if s.missing[i]:
                detail = "only one file has a value there"
            else:
                detail = (f"result {_g(s.result[i], 7)}, reference {_g(s.reference[i], 7)}, "
                          f"allowed [{_g(s.lower[i], 7)}, {_g(s.upper[i], 7)}]")
            frac = s.n_outside / s.n_points
            lines.append(f"FAIL {s.name}: {s.n_outside} of {s.n_points} points outside "
                         f"({100 * frac:.1f}%), first at t = {s.time[s.outside][0]:g} s, worst "
                         f"at t = {s.time[i]:g} s: {detail}")
        lines.append(f"FAIL: {len(failed)} of {len(c.signals)} signals outside the tolerance "
                     f"band ({_names([s.name for s in failed])})")
    elif not quiet:
        lines.append("")
        lines.append(f"PASS: all {len(c.signals)} signals within the tolerance band")
    return "\n".join(lines)
