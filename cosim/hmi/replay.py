"""A finished run as its page shows it: :func:`load` reads a run's folder (``results.csv``,
``timings.csv``, ``summary.json`` and ``operator.csv``, as ``cosim run`` writes them) into a
:class:`~cosim.hmi.feed.Feed` that the same page replays with a time slider."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.csvio import read_table
from cosim.core.errors import CosimError
from cosim.core.operator import AUDIT_FILE
from cosim.hmi.feed import Feed, Layout, SignalInfo

__all__ = ["is_run_folder", "load", "read_summary"]


def is_run_folder(path: Path) -> bool:
    """Whether ``path`` holds a run (its ``summary.json`` and ``results.csv``)."""
    return (path / "summary.json").is_file() and (path / "results.csv").is_file()


def read_summary(path: Path) -> dict[str, Any]:
    """A run's ``summary.json``.

    Raises
    ------
    CosimError
        Unreadable, or not a JSON object.
    """
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CosimError(f"{path}: cannot read: {exc}") from None
    if not isinstance(doc, dict):
        raise CosimError(f"{path}: not a run's summary (a JSON object)")
    return doc


def _signals(doc: dict[str, Any], kind: str) -> list[SignalInfo]:
    out = []
    for name, s in ((doc.get("signals") or {}).get(kind) or {}).items():
        s = s if isinstance(s, dict) else {}
        lo, hi = s.get("min"), s.get("max")
        out.append(SignalInfo(str(name), str(s.get("unit") or ""),
                              math.nan if lo is None else float(lo),
                              math.nan if hi is None else float(hi)))
    return out


def _rows(path: Path) -> tuple[list[str], list[list[float]]]:
    """The columns and rows of a result CSV (``time`` first)."""
    table = read_table(path)
    values = [table.time, *(table.column(n) for n in table.names)]
    return [table.time_name, *table.names], np.column_stack(values).tolist()


def load(folder: str | Path, flag: str = "RESULTS_DIR") -> Feed:
    """The feed of the finished run in ``folder``.

    Raises
    ------
    CosimError
        ``folder`` is not a run's folder, or one of its files cannot be read (one line
        naming the file).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise CosimError(f"{flag} {folder}: no such folder")
    if not is_run_folder(folder):
        raise CosimError(f"{flag} {folder}: not a run's folder (no summary.json and "
                         "results.csv; cosim run --out writes them) nor a campaign's")
    doc = read_summary(folder / "summary.json")
    columns, rows = _rows(folder / "results.csv")
    ctrl = doc.get("controller_summary") or {}
    grade = ""
    if "certified" in ctrl:
        grade = "certified" if ctrl["certified"] else str(ctrl.get("certificate_reason") or
                                                          "uncertified")
    timing: list[str] = []
    timing_rows: list[list[float]] = []
    if (folder / "timings.csv").is_file():
        names, timing_rows = _rows(folder / "timings.csv")
        timing = [n.removeprefix("ctrl.") for n in names[1:]]
    layout = Layout(title=f"{Path(str(doc.get('scenario', folder.name))).name} · "
                          f"{doc.get('controller', '')}",
                    outputs=_signals(doc, "outputs"), inputs=_signals(doc, "inputs"),
                    step=float(doc.get("step_size") or 0.0),
                    start_time=float(doc.get("start_time") or rows[0][0]),
                    stop_time=float(doc.get("stop_time") or rows[-1][0]),
                    live=bool(doc.get("live")), certificate=grade, timing=timing)
    audit = [(float(r.get("time") or "nan"), r.get("who", ""), r.get("what", ""),
              r.get("old", ""), r.get("new", ""), r.get("result", ""))
             for r in _read_audit(folder / AUDIT_FILE)]
    feed = Feed(layout, audit=audit)
    feed.columns, feed.index = columns, {c: i for i, c in enumerate(columns)}
    feed.rows, feed.timing_rows = rows, timing_rows
    feed.finish(str(doc.get("status", "ok")), str(doc.get("reason") or ""))
    return feed


def _read_audit(path: Path) -> list[dict[str, str]]:
    """The rows of an ``operator.csv``; empty when there is none.

    Raises
    ------
    CosimError
        The file exists but cannot be read.
    """
    import csv

    if not path.exists():
        return []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise CosimError(f"{path}: cannot read: {exc}") from None
