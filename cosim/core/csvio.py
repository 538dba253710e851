"""CSV files in and out: one reader with ``file:line:column`` errors, and the writers.

Reading
-------
:class:`CsvReader` reads every CSV file of this project (scenarios, result files, data sets)
row by row and turns each fault of the file itself into a one-line
:class:`~cosim.core.errors.CosimError`: missing, a folder, unreadable, not text, malformed CSV,
empty, a row with the wrong number of cells, a cell that is not a number. What a file
*means* (what a blank cell is, time order, column names) stays with its user
(:mod:`cosim.core.scenario`, :mod:`cosim.core.datagen`, :func:`read_table`). Each kind of file words
these errors its own way (a :class:`Wording`), so the messages users know are kept.

:func:`read_table` reads a result CSV (``results.csv``, a regression reference) into a
:class:`Table`: the format of the FMI cross-check rules below, time first.

Writing
-------
* :func:`write_csv` (with :func:`header_line` and :func:`row_lines` for streaming): the FMI
  cross-check format of ``results.csv`` and ``timings.csv``: comma separated, the header's
  names in double quotes, numbers unquoted in full precision (``repr``), ``\\n`` line ends;
  written atomically (:mod:`cosim.core.atomicio`).
* :func:`write_table`: the :mod:`csv` module's default (``excel``) dialect, used by the data
  sets of :mod:`cosim.core.datagen`: cells quoted only when needed, ``\\r\\n`` line ends, floats in
  full precision (``repr``), other cells as text.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from cosim.core import atomicio
from cosim.core.errors import CosimError

__all__ = [
    "RESULT_WORDING",
    "CsvReader",
    "Table",
    "Wording",
    "header_line",
    "parse_number",
    "read_table",
    "row_lines",
    "write_csv",
    "write_table",
]


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Wording:
    """The error messages of one kind of CSV file, as :meth:`str.format` templates.

    Every template may use ``{path}``; the others, where they apply: ``{error}`` (the
    exception's text), ``{strerror}`` (the operating system's message), ``{reason}`` and
    ``{start}`` (of a byte that is not UTF-8); ``{line}`` (1-based; for ``not_text`` the line
    being read) and ``{col}``; ``{cells}`` and ``{expected}`` (cell counts); ``{name}`` (the
    column) and ``{cell}`` (the cell's text, stripped). The defaults are those of a result
    CSV (:func:`read_table`).

    Attributes
    ----------
    not_found, is_folder, unreadable : str
        The file is missing, is a folder, or cannot be opened or read.
    not_text, malformed : str
        A byte that is not UTF-8; a :class:`csv.Error` (e.g. a field over the size limit).
    empty : str
        Not even a header row.
    cell_count : str
        A row whose number of cells is not the header's; ``{col}`` is the first cell too
        many or missing.
    empty_value, not_a_number, not_finite : str
        A number cell that is blank (``None``: worded as ``not_a_number``), is not a number,
        or is NaN or infinite where a finite number is required.
    """

    not_found: str = "{path}: no such file"
    is_folder: str = "{path}: is a directory, expected a CSV file"
    unreadable: str = "{path}: cannot read: {strerror}"
    not_text: str = "{path}: not a text CSV file ({reason})"
    malformed: str = "{path}: malformed CSV: {error}"
    empty: str = "{path}:1:1: empty file, expected a header row"
    cell_count: str = "{path}:{line}:1: {cells} cells, the header has {expected}"
    empty_value: str | None = "{path}:{line}:{col}: empty value in column '{name}'"
    not_a_number: str = "{path}:{line}:{col}: '{cell}' is not a number (column '{name}')"
    not_finite: str = "{path}:{line}:{col}: {cell} is not a finite number (column '{name}')"


#: The wording of a result CSV (``results.csv``, references): :func:`read_table`.
RESULT_WORDING = Wording()


def _error(path: Path, template: str, exc: BaseException | None = None,
           **fields: Any) -> CosimError:
    """The :class:`CosimError` of ``template`` filled in for ``path`` (and ``exc``)."""
    if exc is not None:
        fields.setdefault("error", exc)
        fields.setdefault("strerror", getattr(exc, "strerror", None))
        fields.setdefault("reason", getattr(exc, "reason", None))
        fields.setdefault("start", getattr(exc, "start", None))
    return CosimError(template.format(path=path, **fields))


def parse_number(path: Path, wording: Wording, cell: str, line: int, col: int, name: str,
                 finite: bool = True) -> float:
    """The float in ``cell`` (surrounding blanks ignored).

    Raises
    ------
    CosimError
        Worded by ``wording`` (``empty_value``, ``not_a_number``, ``not_finite``), naming
        ``path:line:col`` and the column ``name``.
    """
    text = cell.strip()
    where = dict(line=line, col=col, name=name, cell=text)
    if not text and wording.empty_value is not None:
        raise _error(path, wording.empty_value, **where)
    try:
        value = float(text)
    except ValueError:
        raise _error(path, wording.not_a_number, **where) from None
    if finite and not math.isfinite(value):
        raise _error(path, wording.not_finite, **where)
    return value


class CsvReader:
    """One CSV file, read row by row, with every fault of the file as a :class:`CosimError`.

    A context manager (it closes the file)::

        with CsvReader(path, wording) as f:
            header = f.header()
            for line, cells in f.rows(len(header)):
                t = f.number(cells[0], line, 1, "time")

    Parameters
    ----------
    path : str or Path
    wording : Wording
        The messages of this kind of file.
    encoding : str
        ``"utf-8"``, or ``"utf-8-sig"`` to drop a byte-order mark.
    whole_file : bool
        Read the whole file at once and split it with :meth:`str.splitlines` (scenario
        files): a byte that is not UTF-8 is then reported before any row, and a quoted cell
        that spans lines is refused (``malformed``). Default: read line by line, as the
        :mod:`csv` module does.

    Raises
    ------
    CosimError
        The file is missing, a folder or cannot be opened (``not_found``, ``is_folder``,
        ``unreadable``); with ``whole_file``, also ``not_text`` and ``unreadable`` when it
        cannot be read.
    """

    def __init__(self, path: str | Path, wording: Wording = RESULT_WORDING,
                 encoding: str = "utf-8", whole_file: bool = False) -> None:
        self.path = Path(path)
        self.wording = wording
        try:
            self._fh: IO[str] = self.path.open(newline="", encoding=encoding)
        except FileNotFoundError as exc:
            raise self.error(wording.not_found, exc) from None
        except IsADirectoryError as exc:
            raise self.error(wording.is_folder, exc) from None
        except OSError as exc:
            raise self.error(wording.unreadable, exc) from None
        source: Iterable[str] = self._fh
        if whole_file:
            with self._fh:
                try:
                    source = self._fh.read().splitlines()
                except UnicodeDecodeError as exc:
                    raise self.error(wording.not_text, exc, line=1) from None
                except OSError as exc:
                    raise self.error(wording.unreadable, exc) from None
        self._reader = csv.reader(source)
        self._whole_file = whole_file

    def __enter__(self) -> CsvReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the file."""
        self._fh.close()

    @property
    def line(self) -> int:
        """Lines read so far (the last line of the row just read)."""
        return self._reader.line_num

    def error(self, template: str, exc: BaseException | None = None,
              **fields: Any) -> CosimError:
        """A :class:`CosimError` worded by ``template`` (one of :attr:`wording`'s fields)."""
        return _error(self.path, template, exc, **fields)

    def _next(self) -> list[str] | None:
        """The next row's cells, or ``None`` at the end of the file."""
        first = self.line + 1
        try:
            row = next(self._reader, None)
            if self._whole_file and self.line > first:
                # split into lines first, the reader would join them without the break
                raise csv.Error(f"a quoted cell spans lines {first} to {self.line}")
            return row
        except UnicodeDecodeError as exc:
            raise self.error(self.wording.not_text, exc, line=self.line + 1) from None
        except csv.Error as exc:
            raise self.error(self.wording.malformed, exc, line=self.line) from None
        except OSError as exc:
            raise self.error(self.wording.unreadable, exc) from None

    def header(self) -> list[str]:
        """The first row, as written (not stripped).

        Raises
        ------
        CosimError
            ``empty`` when the file has no row at all.
        """
        row = self._next()
        if row is None:
            raise self.error(self.wording.empty, line=1)
        return row

    def rows(self, expected: int, skip_blank: bool = True) -> Iterator[tuple[int, list[str]]]:
        """``(line, cells)`` of each row after the header, each with ``expected`` cells.

        Parameters
        ----------
        expected : int
            Cells per row (the header's).
        skip_blank : bool
            Skip rows whose cells are all blank (else such a row has the wrong count).

        Raises
        ------
        CosimError
            ``cell_count`` for a row with another number of cells; ``not_text``,
            ``malformed`` or ``unreadable`` when the file cannot be read on.
        """
        while (row := self._next()) is not None:
            line = self.line
            if skip_blank and not any(cell.strip() for cell in row):
                continue
            if len(row) != expected:
                raise self.error(self.wording.cell_count, line=line,
                                 col=min(len(row), expected) + 1, cells=len(row),
                                 expected=expected)
            yield line, row

    def number(self, cell: str, line: int, col: int, name: str, finite: bool = True) -> float:
        """:func:`parse_number` for a cell of this file."""
        return parse_number(self.path, self.wording, cell, line, col, name, finite)


# --------------------------------------------------------------------------------------------
# Result CSVs
# --------------------------------------------------------------------------------------------

@dataclass
class Table:
    """A result CSV: the time column parsed, signal columns parsed on demand.

    Attributes
    ----------
    path : Path
    time_name : str
        Header of the first column.
    names : list of str
        Signal column headers, in file order (time excluded).
    time : ndarray
        Strictly increasing times [s].
    """

    path: Path
    time_name: str
    names: list[str]
    time: np.ndarray
    _rows: list[list[str]] = field(repr=False)
    _lines: list[int] = field(repr=False)
    _cache: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def column(self, name: str) -> np.ndarray:
        """Values of one signal column as floats.

        Raises
        ------
        CosimError
            ``file:line:column: ...`` for an empty or non-numeric cell.
        """
        if name in self._cache:
            return self._cache[name]
        try:
            j = self.names.index(name) + 1
        except ValueError:
            raise CosimError(f"{self.path}: no column '{name}'") from None
        values = np.empty(len(self._rows))
        for i, row in enumerate(self._rows):
            values[i] = parse_number(self.path, RESULT_WORDING, row[j], self._lines[i], j + 1,
                                     name, finite=False)
        self._cache[name] = values
        return values


def read_table(path: str | Path) -> Table:
    """Read a result CSV, checking the header, the row lengths and the time column.

    Raises
    ------
    CosimError
        One line naming the file (and ``line:column`` where it applies): missing or
        unreadable file, empty file, duplicate or empty column names, a row with the wrong
        number of cells, a non-numeric or non-finite time, non-increasing time, no data rows.
    """
    path = Path(path)
    with CsvReader(path, RESULT_WORDING) as f:
        header = [h.strip() for h in f.header()]
        rows: list[list[str]] = []
        lines: list[int] = []
        for line, row in f.rows(len(header)):
            rows.append(row)
            lines.append(line)

    if len(header) < 2:
        raise CosimError(f"{path}:1:1: expected a time column and at least one signal column")
    seen: dict[str, int] = {}
    for j, name in enumerate(header, start=1):
        if not name:
            raise CosimError(f"{path}:1:{j}: empty column name")
        if name in seen:
            raise CosimError(f"{path}:1:{j}: duplicate column '{name}' (also column {seen[name]})")
        seen[name] = j
    if not rows:
        raise CosimError(f"{path}:2:1: no data rows")

    time = np.empty(len(rows))
    for i, row in enumerate(rows):
        t = parse_number(path, RESULT_WORDING, row[0], lines[i], 1, header[0], finite=False)
        if not math.isfinite(t):
            raise CosimError(f"{path}:{lines[i]}:1: time must be finite, got '{row[0].strip()}'")
        if i and t <= time[i - 1]:
            raise CosimError(f"{path}:{lines[i]}:1: time {t:g} is not greater than the previous "
                             f"time {time[i - 1]:g} (line {lines[i - 1]}); times must increase")
        time[i] = t
    return Table(path, header[0], header[1:], time, rows, lines)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

def header_line(columns: Sequence[str]) -> str:
    """The cross-check header row: every name in double quotes (``"`` doubled), with ``\\n``."""
    return ",".join('"' + c.replace('"', '""') + '"' for c in columns) + "\n"


def row_lines(rows: Iterable[Sequence[float]], width: int | None = None) -> str:
    """Cross-check data rows: floats in full precision (``repr``), each line ending in ``\\n``.

    With ``width`` every row is cut or padded (with ``nan``) to that many cells.
    """
    rep = float.__repr__
    if width is None:
        return "".join(",".join([rep(float(v)) for v in row]) + "\n" for row in rows)
    pad = ["nan"] * width
    return "".join(",".join(([rep(float(v)) for v in row[:width]] + pad)[:width]) + "\n"
                   for row in rows)


def write_csv(path: str | Path, columns: Sequence[str], rows: Iterable[Sequence[float]]
              ) -> None:
    """Write rows in the cross-check CSV format (see the module docstring), atomically.

    Raises
    ------
    OutputError
        The file could not be written; a previous ``path`` is intact.
    """
    with atomicio.open_replacing(path, "w", newline="\n") as f:
        f.write(header_line(columns))
        f.write(row_lines(rows))


def write_table(fh: IO[str], header: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    """Write a header and rows in the :mod:`csv` module's default dialect to ``fh``.

    ``fh`` must be opened with ``newline=""``. Floats (numpy's too) are written in full
    precision (``repr``); every other cell as text.
    """
    writer = csv.writer(fh)
    writer.writerow(header)
    for row in rows:
        writer.writerow([repr(float(v)) if isinstance(v, float) else v for v in row])

