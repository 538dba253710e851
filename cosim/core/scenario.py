"""Scenario CSV files: set-points and perturbations as piecewise-constant signals.

Format (one file per scenario)::

    time,ref.h1,ref.h2,plant.qd1,sensor.h1.bias,sensor.h2.noise
    0,0.8,0.8,,,
    5000,1.0,,,,
    7500,,,-1e-5,0.02,
    15000,,,,,

* The first column is ``time`` [s]; rows are in strictly increasing time. The first row's
  time is the start time and the last row's time is the stop time.
* Each other column is one signal; a value holds until the next row that sets it (piecewise
  constant, zero-order hold); a blank cell means "unchanged".
* Column names: ``ref.<output>`` set-points (every reference needs a value in the first row),
  ``plant.<variable>`` a plant input or tunable parameter (by its FMU name or by the name of
  a variable-map signal), ``sensor.<output>.bias`` an additive measurement bias and
  ``sensor.<output>.noise`` the standard deviation of seeded Gaussian measurement noise,
  ``sensor.<output>.uniform`` the half-width ``a`` of seeded measurement noise uniform in
  ``[−a, a]`` (a bounded perturbation, as ``w_y`` in the paper), ``op.<setting>`` an operator
  action on the controller (``op.mode``: ``auto`` or ``manual``; ``op.service.<input>``,
  ``op.manual.<input>``, ``op.control.<output>``, ``op.min.<signal>``, ``op.max.<signal>``:
  :mod:`controllers.operator`), checked and recorded by :mod:`cosim.core.operator`.
* Comma separated, header names may be quoted (FMI cross-check CSV conventions).

Every error is a :class:`~cosim.core.errors.CosimError` that starts with ``file:line:column``
(1-based; the header is line 1) and names the column.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from cosim.core import csvio
from cosim.core.component import Schedule
from cosim.core.errors import CosimError
from cosim.core.operator import MODE_WORDS

__all__ = ["BIAS", "DIST", "NOISE", "OP", "PLANT", "REF", "SCENARIO_WORDING", "SENSOR_KINDS",
           "UNIFORM", "Column", "Event", "Scenario", "load"]

#: Column kinds.
REF, PLANT, BIAS, NOISE, UNIFORM = "ref", "plant", "bias", "noise", "uniform"
#: ``dist.<name>``: a measured disturbance, set on the plant and measured by the controller.
DIST = "dist"
#: ``op.<setting>``: an operator action on the controller (its target: the setting's name).
OP = "op"
#: The suffixes of ``sensor.<output>.<suffix>`` columns, by kind.
SENSOR_KINDS = {"bias": BIAS, "noise": NOISE, "uniform": UNIFORM}


@dataclass(frozen=True)
class Column:
    """One signal column of a scenario.

    Attributes
    ----------
    index : int
        1-based column number in the file (``time`` is column 1).
    name : str
        The header as written, e.g. ``"sensor.h1.bias"``.
    kind : str
        :data:`REF`, :data:`PLANT`, :data:`DIST`, :data:`BIAS`, :data:`NOISE` or
        :data:`UNIFORM`.
    target : str
        The signal it acts on: ``"h1"`` for ``ref.h1`` and ``sensor.h1.bias``, ``"qd1"`` for
        ``plant.qd1``, ``"Tin"`` for ``dist.Tin``.
    """

    index: int
    name: str
    kind: str
    target: str


@dataclass(frozen=True)
class Event:
    """The values a scenario row sets at ``time`` (only the non-blank cells)."""

    time: float
    line: int
    values: tuple[tuple[Column, float], ...]


@dataclass
class Scenario:
    """A parsed scenario: columns and events, first event at the start time.

    Use :func:`load` to read one and :meth:`validate` once the plant's and the controller's
    signals are known.
    """

    path: Path
    columns: tuple[Column, ...]
    events: tuple[Event, ...]
    meta: dict = field(default_factory=dict)

    @property
    def start_time(self) -> float:
        """Time of the first row [s]."""
        return self.events[0].time

    @property
    def stop_time(self) -> float:
        """Time of the last row [s]."""
        return self.events[-1].time

    def columns_of(self, kind: str) -> tuple[Column, ...]:
        """The columns of one kind, in file order."""
        return tuple(c for c in self.columns if c.kind == kind)

    def setpoints(self) -> list[dict[str, float]]:
        """The set-points the scenario requests, in the order they come: after each row that
        sets a ``ref.<output>``, every output's set-point then in force (an output not set yet
        is left out; a repeated set-point is listed once)."""
        held: dict[str, float] = {}
        out: list[dict[str, float]] = []
        for event in self.events:
            changed = False
            for col, value in event.values:
                if col.kind == REF and held.get(col.target) != value:
                    held[col.target] = value
                    changed = True
            if changed and held not in out:
                out.append(dict(held))
        return out

    def schedule(self, kind: str, target: str, default: float) -> Schedule:
        """The value the run sets for column ``<kind>.<target>`` at any time ``t``, as data
        (:class:`~cosim.core.component.Schedule`): the last row at or before ``t`` that gives
        it (rows hold until the next), ``default`` before the first (and for a column the
        file does not have). What a controller that knows a measured disturbance ahead is
        given (``preview = true``)."""
        times, values = [], []
        for event in self.events:
            for col, value in event.values:
                if col.kind == kind and col.target == target:
                    times.append(event.time)
                    values.append(float(value))
        return Schedule(tuple(times), tuple(values), float(default))

    def perturbation_times(self) -> list[float]:
        """Times (after the start) at which a ``plant.*`` or ``sensor.*`` value changes."""
        times = []
        for event in self.events[1:-1]:
            if any(col.kind not in (REF, OP) for col, _ in event.values):
                times.append(event.time)
        return times

    def reference_times(self) -> list[float]:
        """Times (after the start) at which a set-point is set."""
        return [e.time for e in self.events[1:-1] if any(c.kind == REF for c, _ in e.values)]

    def with_changes(self, at_start: Mapping[str, float] | None = None,
                     setpoints: Sequence[tuple[float, Mapping[str, float]]] | None = None,
                     stop_time: float | None = None,
                     disturbances: Sequence[tuple[float, Mapping[str, float]]] | None = None,
                     operator: Sequence[tuple[float, Mapping[str, float]]] | None = None
                     ) -> Scenario:
        """A copy with values set in the first row, the set-points replaced, or a new stop.

        Parameters
        ----------
        at_start : mapping, optional
            Column name (``plant.a1``, ``sensor.h1.noise``, ``ref.h1``, ``op.mode``) → value
            applied at the start time, replacing the first row's value of an existing column or
            adding a column; later rows keep their values.
        setpoints : sequence of (time, {output: value}), optional
            Replace every ``ref.*`` value of the scenario by these set-point changes.
        stop_time : float, optional
            New stop time; later events are dropped.
        disturbances : sequence of (time, {disturbance: value}), optional
            Replace every ``dist.*`` value of the scenario by these changes.
        operator : sequence of (time, {op.<setting>: value}), optional
            Operator actions added to the scenario's (a campaign's ``[operator]`` events).

        Raises
        ------
        CosimError
            A column name that is not a scenario column, or a stop time not after the start.
        """
        start = self.start_time
        stop = self.stop_time if stop_time is None else float(stop_time)
        if not stop > start:
            raise CosimError(f"{self.path}: stop time {stop!r} is not after the start time "
                             f"{start!r}")
        columns = list(self.columns)
        by_name = {c.name: c for c in columns}
        names = list(at_start or {})
        if setpoints:
            names += [f"ref.{o}" for _, values in setpoints for o in values]
        if disturbances:
            names += [f"dist.{d}" for _, values in disturbances for d in values]
        if operator:
            names += [name for _, values in operator for name in values]
        new = [n for n in dict.fromkeys(names) if n not in by_name]
        if new:
            parsed = _parse_header(self.path, ["time", *new])
            for c in parsed:
                col = Column(len(columns) + 2, c.name, c.kind, c.target)
                columns.append(col)
                by_name[col.name] = col
        table: dict[float, dict[str, float]] = {}
        lines: dict[float, int] = {}
        for event in self.events:
            if event.time > stop + 1e-9 * max(1.0, abs(stop)):
                break
            row = table.setdefault(event.time, {})
            lines[event.time] = event.line
            for col, value in event.values:
                if not ((setpoints and col.kind == REF)
                        or (disturbances and col.kind == DIST)):
                    row[col.name] = value
        table.setdefault(start, {}).update(at_start or {})
        for prefix, changes in (("ref.", setpoints), ("dist.", disturbances), ("", operator)):
            for t, values in changes or ():
                if start <= t < stop:
                    table.setdefault(float(t), {}).update(
                        {f"{prefix}{o}": v for o, v in values.items()})
        table.setdefault(stop, {})
        events = []
        for t in sorted(table):
            if t > stop:
                continue
            values = tuple((by_name[n], v) for n, v in table[t].items())
            events.append(Event(t, lines.get(t, 0), values))
        return Scenario(path=self.path, columns=tuple(columns), events=tuple(events),
                        meta=dict(self.meta))

    def validate(
        self,
        plant_settable: Collection[str],
        controller_refs: Collection[str],
        measured: Collection[str] = (),
        driven: Collection[str] = (),
        plant_tunable: Collection[str] | None = None,
        disturbances: Collection[str] = (),
        operator: Callable[[str, float], str] | None = None,
    ) -> None:
        """Check every column name against the run's signals, and every operator action.

        Parameters
        ----------
        plant_settable : collection of str
            Plant inputs and tunable parameters a ``plant.<name>`` column may set.
        controller_refs : collection of str
            Outputs the controller takes a set-point for (``h1`` for input ``ref.h1``).
        measured : collection of str
            Measured plant outputs a ``sensor.<name>.*`` column may perturb.
        driven : collection of str
            Plant inputs driven by the controller (a scenario must not set them).
        plant_tunable : collection of str, optional
            The subset of ``plant_settable`` that may change after the first row (inputs and
            tunable parameters); default: all of ``plant_settable``.
        disturbances : collection of str
            The measured disturbances a ``dist.<name>`` column may set (the problem's).
        operator : callable, optional
            Why an operator action ``op.<setting>`` = value is refused before the controller
            sees it (:meth:`cosim.core.operator.OperatorDesk.check`; ``""``: it is not);
            ``None``: the controller takes none.

        Raises
        ------
        CosimError
            ``file:1:col: unknown ...`` for the first column that names nothing known;
            ``file:line:col: ...`` for an operator action refused (a value outside the
            engineer's box, a switch other than 0/1).
        """
        for col in self.columns:
            where = f"{self.path}:1:{col.index}"
            if col.kind == REF and col.target not in controller_refs:
                known = ", ".join(f"ref.{r}" for r in sorted(controller_refs)) or "none"
                raise CosimError(f"{where}: unknown reference '{col.name}': the controller "
                                 f"takes set-points for {known}")
            if col.kind == PLANT:
                if col.target in driven:
                    raise CosimError(f"{where}: column '{col.name}' sets a plant input that "
                                     "the controller drives")
                if col.target not in plant_settable:
                    raise CosimError(f"{where}: unknown plant variable '{col.name}': not an "
                                     "input or tunable parameter of the plant")
            if col.kind == DIST and col.target not in disturbances:
                known = ", ".join(f"dist.{d}" for d in sorted(disturbances)) or "none"
                raise CosimError(f"{where}: unknown disturbance '{col.name}': the problem "
                                 f"measures {known}")
            if col.kind in SENSOR_KINDS.values() and col.target not in measured:
                known = ", ".join(sorted(measured)) or "none"
                raise CosimError(f"{where}: unknown measured output in '{col.name}' "
                                 f"(measured: {known})")
        self._check_operator(operator)
        if plant_tunable is None:
            return
        for event in self.events[1:]:
            for col, _ in event.values:
                if col.kind == PLANT and col.target not in plant_tunable:
                    raise CosimError(
                        f"{self.path}:{event.line}:{col.index}: column '{col.name}': "
                        f"'{col.target}' can only be set in the first row (before "
                        "initialisation); it is not an input or tunable parameter")


    def _check_operator(self, check: Callable[[str, float], str] | None) -> None:
        """Every ``op.*`` cell against ``check`` (``Scenario.validate``'s ``operator``)."""
        for event in self.events:
            for col, value in event.values:
                if col.kind != OP:
                    continue
                where = f"{self.path}:{event.line}:{col.index}"
                why = ("the controller takes no operator settings" if check is None
                       else check(col.target, value))
                if why:
                    raise CosimError(f"{where}: column '{col.name}': {why}")


def _parse_header(path: Path, header: list[str]) -> tuple[Column, ...]:
    if not header or not header[0].strip():
        raise CosimError(f"{path}:1:1: empty header: the first column must be 'time'")
    if header[0].strip() != "time":
        raise CosimError(f"{path}:1:1: the first column must be 'time', not '{header[0]}'")
    columns = []
    seen: dict[str, int] = {}
    for i, raw in enumerate(header[1:], start=2):
        name = raw.strip()
        where = f"{path}:1:{i}"
        if not name:
            raise CosimError(f"{where}: empty column name")
        if name in seen:
            raise CosimError(f"{where}: duplicate column '{name}' (also column {seen[name]})")
        seen[name] = i
        parts = name.split(".")
        if parts[0] == "ref" and len(parts) == 2 and parts[1]:
            columns.append(Column(i, name, REF, parts[1]))
        elif parts[0] == "dist" and len(parts) == 2 and parts[1]:
            columns.append(Column(i, name, DIST, parts[1]))
        elif parts[0] == "plant" and len(parts) >= 2 and all(parts[1:]):
            columns.append(Column(i, name, PLANT, name[len("plant."):]))
        elif (parts[0] == "sensor" and len(parts) >= 3 and parts[-1] in SENSOR_KINDS
              and all(parts[1:-1])):
            columns.append(Column(i, name, SENSOR_KINDS[parts[-1]], ".".join(parts[1:-1])))
        elif parts[0] == "op" and (name == "op.mode" or (len(parts) == 3 and all(parts))):
            columns.append(Column(i, name, OP, name))
        else:
            raise CosimError(
                f"{where}: unknown signal '{name}': expected ref.<output>, dist.<disturbance>, "
                "plant.<variable>, sensor.<output>.bias, sensor.<output>.noise, "
                "sensor.<output>.uniform or op.<setting> (op.mode, op.service.<input>, "
                "op.manual.<input>, op.control.<output>, op.min.<signal>, op.max.<signal>)")
    return tuple(columns)


#: How scenario files word the errors of :class:`~cosim.core.csvio.CsvReader`.
SCENARIO_WORDING = csvio.Wording(
    not_found="{path}: scenario file not found",
    is_folder="{path}: cannot read scenario: {error}",
    unreadable="{path}: cannot read scenario: {error}",
    not_text="{path}: cannot read scenario: {error}",
    malformed="{path}:{line}:1: malformed CSV: {error}",
    empty="{path}:1:1: empty file: expected a header starting with 'time'",
    cell_count="{path}:{line}:{col}: row has {cells} cells, the header has {expected}",
    empty_value=None,
    not_a_number="{path}:{line}:{col}: column '{name}': '{cell}' is not a number",
    not_finite="{path}:{line}:{col}: column '{name}': {cell} is not a finite number",
)


def load(path: str | Path) -> Scenario:
    """Read and check a scenario CSV file (syntax, time, values; names by prefix only).

    Parameters
    ----------
    path : str or Path
        The scenario file.

    Returns
    -------
    Scenario

    Raises
    ------
    CosimError
        ``file:line:column: ...`` for a missing file, a bad header, a non-increasing or
        missing time, a non-numeric, NaN or infinite value, a negative noise level, a
        reference without a first value, a row with the wrong number of cells, an empty body,
        or a stop time not after the start time.
    """
    path = Path(path)
    with csvio.CsvReader(path, SCENARIO_WORDING, encoding="utf-8-sig",
                         whole_file=True) as f:
        columns = _parse_header(path, f.header())
        events: list[Event] = []
        for line, row in f.rows(len(columns) + 1):
            cell = row[0].strip()
            if not cell:
                raise CosimError(f"{path}:{line}:1: column 'time': missing time")
            t = f.number(cell, line, 1, "time")
            if events and t <= events[-1].time:
                raise CosimError(f"{path}:{line}:1: column 'time': time {cell} is not after "
                                 f"the previous row's time {events[-1].time!r}")
            values = []
            for col in columns:
                cell = row[col.index - 1].strip()
                if not cell:
                    if not events and col.kind == REF:
                        raise CosimError(f"{path}:{line}:{col.index}: column '{col.name}': "
                                         "a reference needs a value in the first row")
                    continue
                word = cell.lower()
                v = (MODE_WORDS[word] if col.kind == OP and word in MODE_WORDS
                     else f.number(cell, line, col.index, col.name))
                if col.kind in (NOISE, UNIFORM) and v < 0:
                    what = ("standard deviation" if col.kind == NOISE else "half-width")
                    raise CosimError(f"{path}:{line}:{col.index}: column '{col.name}': noise "
                                     f"{what} {cell} is negative")
                values.append((col, v))
            events.append(Event(t, line, tuple(values)))

    if not events:
        raise CosimError(f"{path}:2:1: empty body: the scenario has no data rows")
    if len(events) < 2:
        raise CosimError(f"{path}:{events[0].line}:1: column 'time': a single row; the last "
                         "row's time is the stop time and must come after the first row's")
    return Scenario(path=path, columns=columns, events=tuple(events))
