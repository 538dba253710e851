"""Writing a run to disk: ``results.csv``, ``timings.csv``, ``operator.csv``, ``summary.json``,
``figure.png``.

While a run goes, :class:`ResultsStream` streams its rows into ``results.csv.part`` in the
output folder, flushed to disk at least once a second of wall time: a run killed outright
(SIGKILL, the OOM killer, a power loss) leaves every row but the last second's there, in the
same CSV format. When the run ends, however it ends (ok, failed, interrupted), :func:`write`
renames that file to ``results.csv`` and writes ``timings.csv``, ``summary.json`` and
``figure.png``, each to a temporary file renamed into place (:mod:`cosim.core.atomicio`): a failed
write leaves the previous file intact. Files of an earlier run in the same folder that this
run does not write (a ``figure.png`` when ``--no-figure`` is given) are removed, so a folder
never mixes two runs.

``results.csv`` follows the FMI cross-check CSV rules (written by
:func:`cosim.core.csvio.write_csv`, re-exported here): comma separated, the header row holds
the column names in double quotes,
``time`` first, numbers unquoted in full precision (Python ``repr``, which round-trips
exactly), one row per communication point, no comments.
Column names are ``<source>.<signal>``: ``ref.h1`` (set-point), ``plant.h1`` (true plant
output, or a plant input/parameter the scenario sets), ``sensor.h1`` (measured value the
controller saw, only when the scenario perturbs it), ``plant.qa`` (the input the plant got),
``ctrl.qa`` (what the controller computed: the same but in manual, out of service or under an
operator limit), ``ctrl.<diagnostic>`` (controller diagnostics; ``nan`` where a step had none).
``operator.csv`` (a run with operator actions, :mod:`cosim.core.operator`): one row per action,
``time, who, what, old, new, result``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from pathlib import Path

from cosim.core import atomicio
from cosim.core import kpis as _kpis
from cosim.core.csvio import header_line, row_lines, write_csv
from cosim.core.errors import OutputError
from cosim.core.master import RunResult

__all__ = ["PART_SUFFIX", "RUN_FILES", "ResultsStream", "jsonable", "signals", "summary", "write",
           "write_csv"]

#: Every file a run writes into its folder (``operator.csv``: the operator's actions, from the
#: scenario, the faceplate or the run's page: :mod:`cosim.core.operator`).
RUN_FILES = ("results.csv", "timings.csv", "operator.csv", "summary.json", "figure.png")
#: Suffix of the file ``results.csv`` is streamed into while the run goes.
PART_SUFFIX = ".part"
#: Most seconds of wall time between two flushes of the streamed rows.
FLUSH_INTERVAL = 1.0


class ResultsStream:
    """``results.csv`` streamed to ``results.csv.part`` as the run goes (a ``RowSink``).

    Rows are buffered and written with ``flush`` + ``fsync`` at least every
    ``flush_interval`` seconds of wall time (and at the first row, with the header).
    :meth:`finish` renames the file onto ``results.csv``. A write that fails (full disk)
    truncates the file back to its last complete row, raises :class:`OutputError` (which
    ends the run) and keeps what was written in ``results.csv.part``.

    Parameters
    ----------
    path : str or Path
        The final ``results.csv``.
    flush_interval : float
        Most seconds between flushes.
    """

    def __init__(self, path: str | Path, flush_interval: float = FLUSH_INTERVAL) -> None:
        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + PART_SUFFIX)
        self.flush_interval = float(flush_interval)
        self.columns: list[str] | None = None
        self.error: OutputError | None = None
        self._fh: object = None
        self._pending: list[list[float]] = []
        self._last = 0.0
        self._good = 0
        self._stale = False

    def append(self, row: list[float], columns: list[str]) -> None:
        """Take one row (``columns`` names its cells); flush when it is time."""
        self._pending.append(row)
        if self.columns is None or time.monotonic() - self._last >= self.flush_interval:
            self.flush(columns)

    def flush(self, columns: list[str]) -> None:
        """Write the buffered rows to disk now."""
        if self.error is not None:
            raise self.error
        fh = self._fh
        pending, self._pending = self._pending, []  # never written twice
        try:
            if fh is None:
                self.columns = list(columns)
                fh = self._fh = open(self.part, "w", encoding="utf-8", newline="\n")  # noqa: SIM115
                os.chmod(self.part, atomicio.FILE_MODE)
                fh.write(header_line(self.columns))
            width = len(self.columns)
            if any(len(r) > width for r in pending):
                self._stale = True  # a diagnostic appeared: finish() rewrites the file
            fh.write(row_lines(pending, width))
            fh.flush()
            os.fsync(fh.fileno())
            self._good = fh.tell()
        except OSError as exc:
            self._fail(exc)
        self._last = time.monotonic()

    def _fail(self, exc: OSError) -> None:
        fh, self._fh = self._fh, None
        if fh is not None:
            with contextlib.suppress(OSError):
                fh.truncate(self._good)  # the file ends with a complete row
            with contextlib.suppress(OSError):
                fh.close()
        kept = f" (rows written so far kept in {self.part.name})" if self._good else ""
        self.error = OutputError(f"{self.path}: cannot write: "
                                 f"{exc.strerror or exc}{kept}")
        raise self.error

    def finish(self, columns: list[str], rows: list[list[float]]) -> None:
        """The run has ended: complete the file and rename it onto ``results.csv``.

        When the columns changed after the header was written (a diagnostic appeared
        mid-run), or nothing was streamed, the file is written again from ``rows``.

        Raises
        ------
        OutputError
            A write failed (also one that failed earlier during the run); ``results.csv``
            is then left as it was.
        """
        if self.error is not None:
            raise self.error
        fh = self._fh
        if fh is None or self._stale or list(columns) != self.columns:
            self.close()
            write_csv(self.path, columns, rows)
            with contextlib.suppress(OSError):
                self.part.unlink()
            return
        self.flush(columns)
        self._fh = None
        try:
            fh.close()
            os.replace(self.part, self.path)
        except OSError as exc:
            raise atomicio.output_error(self.path, exc) from None
        atomicio.fsync_folder(self.path.parent)

    def close(self) -> None:
        """Close the file without renaming it (it stays as ``results.csv.part``)."""
        fh, self._fh = self._fh, None
        if fh is not None:
            with contextlib.suppress(OSError):
                fh.close()


def summary(result: RunResult, meta: dict | None = None) -> dict:
    """The ``summary.json`` document of a run.

    Keys: ``status`` (``ok``/``failed``/``interrupted``), ``reason``, ``steps``,
    ``steps_planned``, ``step_size``, ``start_time``, ``stop_time``, ``wall_time_s``,
    ``signals`` (see :func:`signals`), ``kpis`` (see :func:`cosim.core.kpis.compute`),
    ``controller_summary`` (the controller's own ``summary()``: solver statistics), ``live``
    (a run against a live plant: :mod:`cosim.live.clock`), plus ``meta`` (scenario, plant,
    controller, seed...).
    """
    doc = {
        "status": result.status,
        "reason": result.reason,
        "steps": result.steps,
        "steps_planned": result.steps_planned,
        "step_size": result.step_size,
        "start_time": result.start_time,
        "stop_time": result.stop_time,
        "wall_time_s": round(result.wall_time_s, 6),
    }
    doc.update(meta or {})
    doc["signals"] = signals(result)
    doc["kpis"] = _kpis.compute(result.columns, result.rows, result.outputs, result.references,
                                result.inputs, result.bounds)
    doc["controller_summary"] = result.controller_summary
    if result.live:
        doc["live"] = result.live
    return jsonable(doc)


def signals(result: RunResult) -> dict[str, dict[str, dict]]:
    """The run's controlled outputs and manipulated inputs, with their units and boxes.

    ``{"outputs": {name: {"unit", "min", "max"}}, "inputs": {...}}`` in the controller's
    order (outputs with a set-point first, then the other measured ones); ``unit`` is ``""``
    and ``min``/``max`` are ``None`` where the controller declares none. What the KPIs are
    keyed by, and what a campaign's report labels its figures with.
    """
    def entry(name: str) -> dict:
        lo, hi = result.bounds.get(name, (None, None))
        return {"unit": result.units.get(name, ""), "min": lo, "max": hi}

    outputs = dict.fromkeys([*result.references, *result.outputs])
    return {"outputs": {o: entry(o) for o in outputs},
            "inputs": {u: entry(u) for u in result.inputs}}


def jsonable(obj: object) -> object:
    """``obj`` with JSON types only: numpy scalars as numbers, non-finite floats as ``None``
    (JSON has no NaN), unknown objects as their text."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, bool | int | str) or obj is None:
        return obj
    if hasattr(obj, "dtype") and getattr(obj.dtype, "kind", "") in "iub":
        return obj.item()  # type: ignore[attr-defined]
    try:
        f = float(obj)  # numpy scalars
    except (TypeError, ValueError):
        return str(obj)
    return f if math.isfinite(f) else None


def write(out_dir: str | Path, result: RunResult, meta: dict | None = None,
          figure: bool = True, stream: ResultsStream | None = None) -> dict:
    """Write a run into ``out_dir``: ``results.csv``, ``timings.csv``, ``operator.csv``,
    ``summary.json``, ``figure.png``, each atomically; remove the files of an earlier run it
    does not write.

    Wall-clock diagnostics (the controller's ``timing_diagnostics``, e.g. solve times) go to
    ``timings.csv`` (``time`` then one column each, one row per controller step), so that
    ``results.csv`` is identical across runs of the same scenario.

    Parameters
    ----------
    stream : ResultsStream, optional
        The stream the run's rows went to; it is finished (renamed onto ``results.csv``)
        instead of writing the rows again.

    Returns
    -------
    dict
        The summary document.

    Raises
    ------
    OutputError
        For the first file that could not be written (it keeps its previous content). When
        ``results.csv`` cannot be written nothing else is (the folder keeps the previous run
        whole); otherwise every other file is still tried.

    Notes
    -----
    The figure is best effort: a plotting error is recorded in the summary under
    ``figure_error`` instead of hiding the results.
    """
    out = Path(out_dir)
    errors: list[OutputError] = []
    written: set[str] = set()

    def attempt(name: str, fn: object, *args: object) -> None:
        try:
            fn(*args)  # type: ignore[operator]
            written.add(name)
        except OutputError as exc:
            errors.append(exc)
        except _NotDrawn:
            pass

    if stream is not None:
        attempt("results.csv", stream.finish, result.columns, result.rows)
    else:
        attempt("results.csv", write_csv, out / "results.csv", result.columns, result.rows)
    if errors:
        # no results.csv, so no files that would describe it: the folder keeps the previous
        # run whole (and the rows of this one in results.csv.part)
        raise errors[0]
    if result.timing_columns:
        attempt("timings.csv", write_csv, out / "timings.csv", result.timing_columns,
                result.timing_rows)
    if result.operator_rows:
        attempt("operator.csv", _write_audit, out / "operator.csv", result.operator_rows)
    doc = summary(result, meta)
    if figure:
        attempt("figure.png", _figure, out / "figure.png", result, doc, _title(meta, doc))
    if errors:
        doc["write_error"] = str(errors[0])  # the figure's
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    attempt("summary.json", atomicio.write_text, out / "summary.json", text)
    # an earlier run's files this run did not write would be mistaken for its own
    for name in RUN_FILES:
        if name not in written:
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
    if errors:
        raise errors[0]
    return doc


def _write_audit(path: Path, rows: list[tuple]) -> None:
    """``operator.csv``: the operator's actions (:data:`cosim.core.operator.AUDIT_COLUMNS`),
    one row each, numbers in full precision."""
    import csv
    import io

    from cosim.core.operator import AUDIT_COLUMNS

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(AUDIT_COLUMNS)
    for t, who, what, old, new, result in rows:
        writer.writerow([repr(float(t)), who, what, repr(float(old)), repr(float(new)), result])
    atomicio.write_text(path, buf.getvalue())


def _title(meta: dict | None, doc: dict) -> str:
    """The figure's title: the scenario, and when the controller ran uncertified, why."""
    title = str((meta or {}).get("scenario", ""))
    ctrl = doc.get("controller_summary") or {}
    if ctrl.get("certified") is False:
        reason = str(ctrl.get("certificate_reason") or "")
        reason = reason if len(reason) <= 110 else reason[:107] + "..."
        title += f"\nuncertified (measured tightening, no guarantee): {reason}"
    return title


def _figure(path: Path, result: RunResult, doc: dict, title: str) -> None:
    """Draw the figure atomically; a plotting error goes to ``doc["figure_error"]``."""
    from cosim.core import plots

    with atomicio.replacing(path) as tmp:
        try:
            plots.run_figure(tmp, result, title=title)
        except OSError:
            raise
        except Exception as exc:  # pragma: no cover - plotting must not lose the results
            doc["figure_error"] = f"{type(exc).__name__}: {exc}"
            raise _NotDrawn from None


class _NotDrawn(Exception):
    """The figure could not be drawn (recorded in the summary, not an output error)."""
