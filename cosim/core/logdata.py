"""Identification data logged on a plant: a CSV with a time column, the inputs, the outputs,
one record or several experiments, read for training.

Format
------
A header row, then one row per sample (blank lines skipped; a byte-order mark dropped):

* ``time`` [s]: within one experiment it increases by the problem's ``Ts`` at every row,
  within :data:`TS_TOLERANCE` (relative). The record is not resampled: a log sampled at another
  period, a non-uniform step or time going backwards is an error naming the file, line and
  column. A gap (whole samples missing) ends the experiment: the rows after it are the next
  part of it, an experiment of their own (never joined over the gap).
* one column per input and per output of the control problem, named as in the problem, in
  its units; every cell a finite number, or a missing sample: an empty cell, ``nan``, ``NA``
  or ``null`` drops its row, which ends the experiment there as a gap does (a non-number or
  inf is an error naming file:line:column; so is a missing time).
* ``split`` (optional): ``train``, ``val`` or ``test`` per row, as ``cosim generate-data``
  writes it. Without it, the split is given by fractions (:func:`fraction_split`).
* ``experiment`` (optional): a label per row; the rows of one experiment are consecutive (a
  label that comes back after another is an error). Each experiment is its own time series:
  its time may restart, and it is never joined to the next one (training subsequences stay
  inside it, the open-loop evaluation restarts at its first row).

Any other column is ignored (its name is recorded), and its cells are not read. A data set
written by :func:`cosim.core.datagen.write_csv` is such a file: one experiment with a ``split``
column (the extra plant outputs are ignored columns). Several files are read into one record
by :func:`read_logs`: each file's experiments stay apart from the other files'.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core import csvio
from cosim.core.datagen import DATA_WORDING, SPLITS, Dataset, split_sizes
from cosim.core.errors import CosimError

__all__ = ["EXPERIMENT_COLUMN", "LOG_WORDING", "MISSING", "SPLIT_COLUMN", "TIME_COLUMN",
           "TS_TOLERANCE", "LogData", "fraction_split", "parse_fractions", "read_log",
           "read_logs"]

TIME_COLUMN = "time"
SPLIT_COLUMN = "split"
EXPERIMENT_COLUMN = "experiment"
#: Largest relative deviation of a time step from ``Ts`` (1 %: logger jitter).
TS_TOLERANCE = 0.01
#: Cells of an input or output that mark a missing sample (case-insensitive, stripped).
MISSING = frozenset({"", "nan", "na", "n/a", "null"})

#: How logged data files word the errors of :class:`~cosim.core.csvio.CsvReader`: as data
#: sets do (:data:`~cosim.core.datagen.DATA_WORDING`) the file, its cells by column.
LOG_WORDING = replace(
    DATA_WORDING,
    empty="{path}:1: empty file, expected a header row (time, inputs, outputs)",
    cell_count="{path}:{line}:{col}: {cells} cells, the header has {expected}",
    empty_value="{path}:{line}:{col}: empty value in column '{name}'",
    not_a_number="{path}:{line}:{col}: '{cell}' is not a number (column '{name}')",
    not_finite="{path}:{line}:{col}: {cell} is not a finite number (column '{name}')",
)


@dataclass
class LogData(Dataset):
    """A logged record, the problem's signals only, with its split and experiments: a
    :class:`~cosim.core.datagen.Dataset` (``time`` [s] as logged; ``u``, ``y`` in the
    problem's order and units) with the experiments and provenance.

    Attributes
    ----------
    experiment : (T,) int array
        Index of each row's experiment (0, 1, ... in file order).
    experiment_names : list of str or None
        The labels of the ``experiment`` column (``[None]`` without one).
    lines : (T,) int array
        File line of each row (messages).
    provenance : dict
        Where the data came from (the model file's ``training.data_file``): path, SHA-256,
        rows, columns used and ignored, experiments, split.
    """

    experiment: np.ndarray
    experiment_names: list[str | None]
    lines: np.ndarray
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def n_experiments(self) -> int:
        """Number of experiments."""
        return len(self.experiment_names)


def parse_fractions(text: str, option: str = "--split") -> tuple[float, float]:
    """``"TRAIN,VAL"`` as two fractions (the test part is the rest).

    Raises
    ------
    CosimError
        Naming ``option``, unless both are in (0, 1) with ``TRAIN + VAL < 1``.
    """
    parts = text.split(",")
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        a = b = math.nan
    if not (0 < a < 1 and 0 < b < 1 and a + b < 1):
        raise CosimError(f"{option} must be two fractions TRAIN,VAL with TRAIN > 0, VAL > 0 "
                         f"and TRAIN + VAL < 1 (the test part is the rest), got {text!r}")
    return a, b


def fraction_split(experiment: np.ndarray, fractions: tuple[float, float]) -> np.ndarray:
    """Split labels by fractions, per experiment and in time order.

    The first ``round(N · TRAIN)`` rows of each experiment of ``N`` rows are ``train``, the next
    ``round(N · VAL)`` ``val``, the rest ``test`` (:func:`cosim.core.datagen.split_sizes`, so one
    experiment is split as ``cosim generate-data`` splits its record).
    """
    split = np.empty(experiment.shape[0], dtype=object)
    for e in np.unique(experiment):
        idx = np.flatnonzero(experiment == e)
        split[idx] = np.repeat(np.array(SPLITS), split_sizes(idx.size, fractions))
    return split.astype(str)


def _read_rows(f: Any, path: Path, header: list[str], j_time: int, signals: list[int],
               j_split: int | None, j_exp: int | None
               ) -> tuple[list[list[float]], list[str], list[str], list[int], list[bool]]:
    """The data rows of an open log: per row the time and signal values (NaN for a missing
    sample), its split and experiment labels (when those columns are read), its file line
    and whether a sample is missing."""
    values, split, labels, lines, absent = [], [], [], [], []
    for line, row in f.rows(len(header)):
        cells = [f.number(row[j_time], line, j_time + 1, TIME_COLUMN)]
        gone = False
        for j in signals:
            if row[j].strip().lower() in MISSING:
                gone = True
                cells.append(math.nan)
            else:
                cells.append(f.number(row[j], line, j + 1, header[j]))
        values.append(cells)
        absent.append(gone)
        if j_split is not None:
            label = row[j_split].strip()
            if label not in SPLITS:
                raise CosimError(f"{path}:{line}:{j_split + 1}: split must be one of "
                                 f"{', '.join(SPLITS)}, got {label!r}")
            split.append(label)
        if j_exp is not None:
            label = row[j_exp].strip()
            if not label:
                raise CosimError(f"{path}:{line}:{j_exp + 1}: empty value in column "
                                 f"'{EXPERIMENT_COLUMN}'")
            labels.append(label)
        lines.append(line)
    return values, split, labels, lines, absent


def _assign_split(column: list[str] | None, keep: np.ndarray, experiment: np.ndarray,
                  fractions: tuple[float, float] | None,
                  default_fractions: tuple[float, float], whole_split: str | None
                  ) -> tuple[np.ndarray, str]:
    """The kept rows' split and where it came from: the file's column, the whole file, or
    fractions of each experiment in time order."""
    if column is not None:
        return np.array(column)[keep], f"column '{SPLIT_COLUMN}'"
    if whole_split is not None:
        return np.full(int(np.count_nonzero(keep)), whole_split), f"every row ({whole_split})"
    used = fractions if fractions is not None else default_fractions
    source = (f"fractions {used[0]:g},{used[1]:g} of each experiment in time order"
              + (" (--split)" if fractions is not None else " (default, no split column)"))
    return fraction_split(experiment, used), source


def read_log(path: str | Path, input_names: Sequence[str], output_names: Sequence[str],
             Ts: float, problem: str = "", fractions: tuple[float, float] | None = None,
             default_fractions: tuple[float, float] = (0.75, 0.125),
             missing_hint: str = "", whole_split: str | None = None) -> LogData:
    """Read and check a logged CSV (format: the module docstring) for a control problem.

    Parameters
    ----------
    path : str or Path
    input_names, output_names : sequence of str
        The problem's signals: the columns read.
    Ts : float
        The problem's sample time [s].
    problem : str
        The problem's name (messages, provenance).
    fractions : (float, float), optional
        ``--split TRAIN,VAL``: split by fractions (:func:`fraction_split`) even when the file
        has a ``split`` column.
    default_fractions : (float, float)
        The fractions used when the file has no ``split`` column and ``fractions`` is None.
    missing_hint : str
        Appended to the message of a missing column (e.g. how to name the problem).
    whole_split : str, optional
        Every row is in this split (a file given as ``--val FILE``): its ``split`` column and
        the fractions are not used.

    Raises
    ------
    CosimError
        One line naming the file and line (and column where there is one): unreadable file,
        missing or duplicate column, bad cell, bad split label, an experiment whose rows are
        not consecutive, time not on the ``Ts`` grid.
    """
    path = Path(path)
    what = f"problem {problem!r}" if problem else "the problem"
    with csvio.CsvReader(path, LOG_WORDING, encoding="utf-8-sig") as f:
        header = [h.strip() for h in f.header()]
        col = _columns(path, header, input_names, output_names, what, missing_hint)
        j_time = col[TIME_COLUMN]
        signals = [col[n] for n in (*input_names, *output_names)]
        # with --split fractions (or a whole-file split) the split column is not read
        j_split = col.get(SPLIT_COLUMN) if fractions is None and whole_split is None else None
        j_exp = col.get(EXPERIMENT_COLUMN)
        values, split, labels, lines, absent = _read_rows(f, path, header, j_time, signals,
                                                          j_split, j_exp)
    if not values:
        raise CosimError(f"{path}:2: no data rows")
    arr = np.array(values, dtype=float)
    line_arr = np.array(lines)
    experiment, exp_names = _experiments(path, labels, line_arr, j_exp)
    gaps = _check_time(path, arr[:, 0], experiment, line_arr, Ts, what, j_time + 1,
                       j_exp is not None)
    missing = np.array(absent, dtype=bool)
    if np.all(missing):
        raise CosimError(f"{path}:2: every row misses a sample of an input or output")
    experiment, exp_names = _parts(experiment, exp_names, gaps, missing, path.stem)
    keep = ~missing
    arr, line_arr, experiment = arr[keep], line_arr[keep], experiment[keep]
    split_arr, source = _assign_split(split if j_split is not None else None, keep,
                                      experiment, fractions, default_fractions, whole_split)
    m = len(input_names)
    data = LogData(time=arr[:, 0], u=arr[:, 1:1 + m], y=arr[:, 1 + m:],
                   input_names=list(input_names), output_names=list(output_names),
                   split=split_arr, experiment=experiment, experiment_names=exp_names,
                   lines=line_arr)
    used_cols = {TIME_COLUMN, *input_names, *output_names}
    if j_split is not None:
        used_cols.add(SPLIT_COLUMN)
    if j_exp is not None:
        used_cols.add(EXPERIMENT_COLUMN)
    data.provenance = {
        "path": str(path),
        "sha256": _sha256(path),
        "rows": len(arr),
        "problem": problem,
        "Ts": Ts,
        "columns": {"time": TIME_COLUMN, "inputs": list(input_names),
                    "outputs": list(output_names),
                    "split": SPLIT_COLUMN if j_split is not None else None,
                    "experiment": EXPERIMENT_COLUMN if j_exp is not None else None},
        "ignored_columns": [h for h in header if h not in used_cols],
        "split": {"source": source,
                  "rows": {s: int(np.count_nonzero(split_arr == s)) for s in SPLITS}},
        "gaps": [{"line": int(lines[k]), "missing_samples": n} for k, n in gaps],
        "missing_sample_lines": [int(v) for v in np.array(lines)[missing]],
        "experiments": [_experiment_record(data, e) for e in range(len(exp_names))],
    }
    return data


def read_logs(files: Sequence[tuple[str | Path, str | None]], input_names: Sequence[str],
              output_names: Sequence[str], Ts: float, problem: str = "",
              fractions: tuple[float, float] | None = None,
              default_fractions: tuple[float, float] = (0.75, 0.125),
              missing_hint: str = "") -> LogData:
    """Several logged CSVs as one record: ``files`` holds ``(path, whole_split)`` pairs
    (:func:`read_log`; ``whole_split`` ``None`` for a file split by its column or by
    fractions). Each file's experiments stay apart from the others' (named
    ``<file stem>`` or ``<file stem>:<experiment>``); one file gives :func:`read_log`'s record
    unchanged."""
    parts = [read_log(path, input_names, output_names, Ts, problem, fractions,
                      default_fractions, missing_hint, role) for path, role in files]
    if len(parts) == 1:
        return parts[0]
    names: list[str | None] = []
    experiment = []
    for d in parts:
        stem = Path(d.provenance["path"]).stem
        experiment.append(d.experiment + len(names))
        names += [stem if n is None else f"{stem}:{n}" for n in d.experiment_names]
    data = LogData(time=np.concatenate([d.time for d in parts]),
                   u=np.concatenate([d.u for d in parts]),
                   y=np.concatenate([d.y for d in parts]),
                   input_names=list(input_names), output_names=list(output_names),
                   split=np.concatenate([d.split for d in parts]),
                   experiment=np.concatenate(experiment), experiment_names=names,
                   lines=np.concatenate([d.lines for d in parts]))
    data.provenance = {
        "files": [d.provenance for d in parts],
        "rows": len(data.time),
        "problem": problem,
        "Ts": Ts,
        "split": {"rows": {s: int(np.count_nonzero(data.split == s)) for s in SPLITS}},
    }
    return data


def _columns(path: Path, header: list[str], input_names: Sequence[str],
             output_names: Sequence[str], what: str, hint: str) -> dict[str, int]:
    """Column index of every name of the header; the needed ones must be there."""
    col: dict[str, int] = {}
    for j, name in enumerate(header):
        if not name:
            raise CosimError(f"{path}:1:{j + 1}: empty column name")
        if name in col:
            raise CosimError(f"{path}:1:{j + 1}: duplicate column '{name}' (also column "
                             f"{col[name] + 1})")
        col[name] = j
    needed = [(TIME_COLUMN, "the time [s]"),
              *((n, f"an input of {what}") for n in input_names),
              *((n, f"an output of {what}") for n in output_names)]
    for name, role in needed:
        if name not in col:
            raise CosimError(f"{path}:1: no column '{name}' ({role}); the header has "
                             f"{', '.join(header)}{hint}")
    return col


def _experiments(path: Path, labels: list[str], lines: np.ndarray, j_exp: int | None
                 ) -> tuple[np.ndarray, list[str | None]]:
    """Experiment index per row and the labels; an experiment's rows must be consecutive."""
    if j_exp is None:
        return np.zeros(lines.shape[0], dtype=int), [None]
    index: dict[str, int] = {}
    out = np.empty(len(labels), dtype=int)
    for i, label in enumerate(labels):
        if label not in index:
            index[label] = len(index)
        elif i and labels[i - 1] != label:
            raise CosimError(f"{path}:{lines[i]}:{j_exp + 1}: experiment {label!r} comes back "
                             f"after experiment {labels[i - 1]!r} (line {lines[i - 1]}): the "
                             "rows of one experiment must be consecutive")
        out[i] = index[label]
    return out, list(index)


def _check_time(path: Path, time: np.ndarray, experiment: np.ndarray, lines: np.ndarray,
                Ts: float, what: str, col: int, has_experiments: bool
                ) -> list[tuple[int, int]]:
    """Within each experiment, time steps of ``Ts`` (± :data:`TS_TOLERANCE`); the gaps, as
    ``(row after the gap, samples missing)``."""
    tol = TS_TOLERANCE * Ts
    several = (f"each experiment's rows need their own label in an '{EXPERIMENT_COLUMN}' "
               "column" if not has_experiments else "give each part its own experiment label")
    gaps: list[tuple[int, int]] = []
    for e in np.unique(experiment):
        idx = np.flatnonzero(experiment == e)
        if idx.size < 2:
            continue
        dt = np.diff(time[idx])
        step = float(np.median(dt))
        if abs(step - Ts) > tol:
            k = idx[1]
            raise CosimError(f"{path}:{lines[k]}:{col}: the data are sampled every {step:g} s "
                             f"(median time step), but {what} has Ts = {Ts:g} s: resample the "
                             "log at Ts, or give the problem of this sample time")
        for b in np.flatnonzero(np.abs(dt - Ts) > tol):
            k, jump = idx[b + 1], float(dt[b])
            at, before = f"{path}:{lines[k]}:{col}", f"{time[k - 1]:g} s (line {lines[k - 1]})"
            if jump <= 0:
                raise CosimError(f"{at}: time {time[k]:g} s does not follow {before}: time "
                                 f"must increase by Ts = {Ts:g} s; for several experiments, "
                                 f"{several}")
            missing = round(jump / Ts) - 1
            if missing >= 1 and abs(jump - (missing + 1) * Ts) <= tol:
                gaps.append((int(k), int(missing)))
                continue
            raise CosimError(f"{at}: non-uniform time step of {jump:g} s after {before}, "
                             f"expected Ts = {Ts:g} s (or a whole number of samples missing) "
                             f"within {100 * TS_TOLERANCE:g} %")
    return gaps


def _parts(experiment: np.ndarray, names: list[str | None], gaps: list[tuple[int, int]],
           missing: np.ndarray, stem: str) -> tuple[np.ndarray, list[str | None]]:
    """The experiments cut at the gaps and at the rows with a missing sample (those rows
    belong to none: the caller drops them): an index per row and the names (a part after a
    cut is ``<name>#2``, ``#3``, …; ``<name>`` is the label, or the file's stem)."""
    cut = np.zeros(len(experiment), dtype=bool)
    for k, _ in gaps:
        cut[k] = True
    out = np.full(len(experiment), -1)
    new_names: list[str | None] = []
    counts: dict[int, int] = {}
    prev = None
    for k in range(len(experiment)):
        if missing[k]:
            continue
        e = int(experiment[k])
        if prev is None or e != prev[0] or cut[k] or prev[1] != k - 1:
            counts[e] = counts.get(e, 0) + 1
            base = names[e]
            new_names.append(base if counts[e] == 1 else f"{base or stem}#{counts[e]}")
        out[k] = len(new_names) - 1
        prev = (e, k)
    if len(new_names) > 1 and new_names[0] is None:
        new_names[0] = stem
    return out, new_names


def _experiment_record(data: LogData, e: int) -> dict[str, Any]:
    """One experiment of the provenance record: label, rows, lines, times, split sizes."""
    idx = np.flatnonzero(data.experiment == e)
    return {"name": data.experiment_names[e], "rows": int(idx.size),
            "lines": [int(data.lines[idx[0]]), int(data.lines[idx[-1]])],
            "time": [float(data.time[idx[0]]), float(data.time[idx[-1]])],
            "split": {s: int(np.count_nonzero(data.split[idx] == s)) for s in SPLITS}}


def _sha256(path: Path) -> str:
    """SHA-256 of the file's bytes (hex)."""
    digest = hashlib.sha256()
    try:
        with path.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        raise CosimError(f"{path}: cannot read data file ({exc.strerror or exc})") from None
    return digest.hexdigest()
