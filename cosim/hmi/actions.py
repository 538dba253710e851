"""What an operator may do to a running loop from its page: the actions, one checked request
each, and the audit of every request.

The page knows a run's switches only through an :class:`Operator`: the list of its
:class:`Action` objects (name, who may, the values it takes, its value now) and one call,
:meth:`Operator.request`, that takes a value from a logged-in :class:`User` and answers
with a :class:`Reply`: accepted (and what was re-derived) or refused with the reason, the
setting unchanged. Requests are made from the run's loop thread, between two steps
(:class:`cosim.hmi.feed.Feed` queues them): the only place a component may be changed.

Today's actions (:class:`RunOperator`): the set-points of the run (operator role; inside the
output's box) and the controller's settings (engineer role; :attr:`~cosim.core.component.
Capability.SETTINGS`: weights, filter gains, checked by the controller's own ``set``). The
operator actions of a controller that declares them (mode, inputs in or out of service,
operator limits; docs: design/hmi.md, "The seam for operator actions") are another
:class:`Operator` that :func:`operator_for` returns for it: the page does not change.

Every request, accepted or refused, is one row of ``operator.csv`` in the run's folder
(:class:`Audit`): time, who, what, old, new, and ``accepted`` or the reason refused.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from cosim.core import atomicio
from cosim.core.component import Capability, Component
from cosim.core.errors import CosimError

__all__ = ["AUDIT_COLUMNS", "AUDIT_FILE", "ROLES", "Action", "Audit", "Operator", "Reply",
           "RunOperator", "User", "operator_for", "read_audit"]

#: The roles, each allowed what the ones before it are: an operator moves set-points (and,
#: with the operator actions, mode, service and limits); an engineer also the settings.
ROLES = ("operator", "engineer")
#: The audit file in a run's folder, and its columns.
AUDIT_FILE = "operator.csv"
AUDIT_COLUMNS = ("time", "who", "what", "old", "new", "result")


@dataclass(frozen=True)
class User:
    """A logged-in user: ``name`` and ``role`` (one of :data:`ROLES`)."""

    name: str
    role: str

    def may(self, role: str) -> bool:
        """Whether this user holds ``role`` or one above it."""
        return self.role in ROLES and ROLES.index(self.role) >= ROLES.index(role)


@dataclass(frozen=True)
class Action:
    """One switch of the page.

    Attributes
    ----------
    name : str
        What it sets: ``ref.<output>`` (a set-point), ``setting.<name>`` (a controller
        setting); the operator actions' own names (``mode``, ``service.<input>``,
        ``op.min.<signal>``) when a controller declares them.
    label : str
        What the page shows.
    role : str
        The least role that may request it (:data:`ROLES`).
    low, high : float
        The range of a number.
    choices : tuple of str
        The values of a choice (a number when empty).
    unit : str
    value : float or str
        Its value now.
    """

    name: str
    label: str
    role: str
    low: float = -math.inf
    high: float = math.inf
    choices: tuple[str, ...] = ()
    unit: str = ""
    value: float | str = math.nan


@dataclass(frozen=True)
class Reply:
    """The answer to a request: ``accepted``, and what was re-derived (accepted) or why it
    was refused, one line."""

    accepted: bool
    text: str = ""


class Operator(Protocol):
    """A run's switches (module docstring). :meth:`request` is called from the loop's
    thread between two steps; :meth:`actions` from any thread."""

    def actions(self) -> list[Action]:
        """The switches, with their values now."""
        ...

    def request(self, action: str, value: float | str, user: User) -> Reply:
        """Set ``action`` to ``value`` for ``user``: checked (the role, the range, the
        controller's own check), applied from the next sample on, or refused unchanged."""
        ...

    def setpoints(self) -> Mapping[str, float]:
        """The set-points accepted since the last call, by output (the loop applies them:
        :meth:`cosim.core.run_result.RunWatcher.between`); empty for none."""
        ...


class RunOperator:
    """Today's switches of a run (module docstring): its set-points and, when the
    controller declares ``SETTINGS``, its settings.

    Parameters
    ----------
    controller : Component
    outputs : sequence of str
        The outputs with a set-point.
    boxes : mapping of str to (float, float)
        Each output's box (the set-points must lie inside).
    units : mapping of str to str
    setpoint_now : callable
        The set-point of an output now (the last row's).
    """

    def __init__(self, controller: Component, outputs: Sequence[str],
                 boxes: Mapping[str, tuple[float, float]], units: Mapping[str, str],
                 setpoint_now: Callable[[str], float]) -> None:
        self.ctrl = controller
        self.outputs = list(outputs)
        self.boxes = dict(boxes)
        self.units = dict(units)
        self.setpoint_now = setpoint_now
        self.settable = Capability.SETTINGS in controller.capabilities
        self._pending: dict[str, float] = {}

    def actions(self) -> list[Action]:
        out = []
        for o in self.outputs:
            lo, hi = self.boxes.get(o, (-math.inf, math.inf))
            out.append(Action(f"ref.{o}", f"set-point {o}", "operator", lo, hi,
                              unit=self.units.get(o, ""), value=self.setpoint_now(o)))
        if self.settable:
            for s in self.ctrl.settings().values():
                out.append(Action(f"setting.{s.name}", s.name, "engineer", s.low, s.high,
                                  unit=s.unit, value=s.start))
        return out

    def request(self, action: str, value: float | str, user: User) -> Reply:
        known = {a.name: a for a in self.actions()}
        act = known.get(action)
        if act is None:
            return Reply(False, f"no action {action!r}")
        if not user.may(act.role):
            return Reply(False, f"user {user.name!r} ({user.role}) may not change {act.label}: "
                                f"it needs the {act.role} role")
        try:
            number = float(value)
        except (TypeError, ValueError):
            return Reply(False, f"{act.label}: {value!r} is not a number")
        if not (math.isfinite(number) and act.low <= number <= act.high):
            return Reply(False, f"{act.label} = {number:g}: outside [{act.low:g}, {act.high:g}]"
                                f" {act.unit}".rstrip())
        if action.startswith("ref."):
            self._pending[action[4:]] = number
            return Reply(True, f"{act.label} = {number:g} {act.unit}".rstrip())
        try:
            return Reply(True, self.ctrl.set(action[len("setting."):], number))
        except CosimError as exc:
            return Reply(False, str(exc))

    def setpoints(self) -> dict[str, float]:
        out, self._pending = self._pending, {}
        return out


def operator_for(controller: Component, outputs: Sequence[str],
                 boxes: Mapping[str, tuple[float, float]], units: Mapping[str, str],
                 setpoint_now: Callable[[str], float]) -> Operator:
    """The switches of a run of ``controller``: :class:`RunOperator` (the seam where a
    controller that declares the operator actions gets its own :class:`Operator`)."""
    return RunOperator(controller, outputs, boxes, units, setpoint_now)


class Audit:
    """``operator.csv`` of a run (module docstring): each request one row, written and
    flushed as it is answered; nothing is written (no file) before the first.

    Parameters
    ----------
    path : Path or None
        The file; ``None``: the rows are kept in :attr:`rows` only (a run without a folder).
    """

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.rows: list[tuple[float, str, str, Any, Any, str]] = []
        #: whether the file holds this run's rows
        self.written = False
        self._fh: Any = None

    def record(self, t: float, who: str, what: str, old: Any, new: Any, reply: Reply) -> None:
        """One request's row."""
        row = (float(t), who, what, old, new, "accepted" if reply.accepted else reply.text)
        self.rows.append(row)
        if self.path is None:
            return
        try:
            if self._fh is None:
                self._fh = open(self.path, "w", encoding="utf-8", newline="")  # noqa: SIM115
                self.written = True
                os.chmod(self.path, atomicio.FILE_MODE)
                csv.writer(self._fh).writerow(AUDIT_COLUMNS)
            csv.writer(self._fh).writerow([repr(row[0]), *row[1:]])
            self._fh.flush()
            os.fsync(self._fh.fileno())
        except OSError as exc:
            raise atomicio.output_error(self.path, exc) from None

    def close(self) -> None:
        """Close the file (idempotent)."""
        fh, self._fh = self._fh, None
        if fh is not None:
            fh.close()


def read_audit(path: Path) -> list[dict[str, str]]:
    """The rows of an ``operator.csv`` (a replay's); empty when there is none.

    Raises
    ------
    CosimError
        The file exists but cannot be read.
    """
    if not path.exists():
        return []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise CosimError(f"{path}: cannot read: {exc}") from None
