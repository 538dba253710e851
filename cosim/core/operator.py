"""The operator's desk: the one checked entry for every operator action on a running
controller (issue 61; docs: guide/operating.md).

A scenario row's ``op.*`` cells, a write on the controller's OPC UA faceplate
(:mod:`cosim.live.faceplate`) and a request from the run's page (:mod:`cosim.hmi.actions`)
all go through :meth:`OperatorDesk.act`: the
action is checked against the user's role and the setting's range (a value outside it is
refused before the controller sees it), handed to the controller
(:meth:`cosim.core.component.Component.set`: it refuses, in the user's words, what its
certificate cannot cover, the previous setting kept), and recorded as one row of the run's
audit log, ``operator.csv``: time, who, what, old, new, and ``accepted`` or the reason it
was refused.

What may be changed is the controller's declaration (:meth:`Component.settings`: the
operator's ``op.*`` settings, role ``"operator"``; the engineer's weights, role
``"engineer"``) and the run's set-points (``ref.<output>``, role ``"operator"``, inside the
output's box). An operator may change what is the operator's, an engineer everything.

Every run has its desk (:attr:`cosim.core.master.Master.desk`); a set-point accepted is
the loop's from the next sample on (:meth:`attach`: the desk's set-points are the loop's
dict). The desk is shared between the run's loop (the scenario's cells, the page's requests,
answered between two steps) and a faceplate's server thread: :attr:`lock` is held by the
loop while it applies events and steps the controller, and by every :meth:`act`, so that
an action lands between two steps.
"""

from __future__ import annotations

import math
import threading
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.core.component import Capability, Component, Setting
from cosim.core.errors import CosimError

__all__ = ["AUDIT_COLUMNS", "AUDIT_FILE", "MODE_WORDS", "ROLES", "SWITCHES", "Answer",
           "OperatorDesk", "mode_words", "users_table"]

#: ``op.mode``'s words (a scenario cell, a faceplate's string) and their values.
MODE_WORDS = {"auto": 1.0, "manual": 0.0}
#: The roles, each with what it may change (the settings' roles).
ROLES = {"operator": ("operator",), "engineer": ("operator", "engineer")}


#: The audit log in a run's folder, and its columns.
AUDIT_FILE = "operator.csv"
AUDIT_COLUMNS = ("time", "who", "what", "old", "new", "result")
#: The settings that are switches (1 or 0): the mode, an input in service, an output
#: controlled (a name, or the prefix of the names).
SWITCHES = ("op.mode", "op.service.", "op.control.")


def users_table(path: Path, flag: str, keys: str) -> dict[str, Any]:
    """The ``[users.<name>]`` tables of the users file at ``path`` (given by option
    ``flag``; ``keys``: what each table holds, for the error), for the page's and the
    faceplate's readers.

    Raises
    ------
    CosimError
        The file is missing, not TOML, or has no user: one line naming the file.
    """
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CosimError(f"{flag} {path}: no such file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise CosimError(f"{flag} {path}: cannot read it: {exc}") from None
    table = doc.get("users")
    if not isinstance(table, dict) or not table:
        raise CosimError(f"{path}: expected [users.<name>] tables with {keys}")
    return table


def mode_words(value: Any) -> Any:
    """``value`` with ``op.mode``'s words (:data:`MODE_WORDS`) as their numbers."""
    if isinstance(value, str) and value.strip().lower() in MODE_WORDS:
        return MODE_WORDS[value.strip().lower()]
    return value


@dataclass(frozen=True)
class Answer:
    """What :meth:`OperatorDesk.act` made of an action: ``accepted``, what the controller
    re-derived or why it was refused (``text``), whether a refusal was the role's
    (``denied``: not this user's to change) or the value's, the setting's value before and
    after."""

    accepted: bool
    text: str
    old: float
    new: float
    denied: bool = False


class OperatorDesk:
    """The one checked entry for operator actions on ``controller`` (module docstring).

    Parameters
    ----------
    controller : Component
        The run's controller: one declaring :attr:`~cosim.core.component.Capability.
        OPERATOR` or ``SETTINGS`` has its settings here; any has the run's set-points.
    """

    def __init__(self, controller: Component) -> None:
        self.controller = controller
        self.lock = threading.RLock()
        #: the audit log's rows (:data:`AUDIT_COLUMNS`)
        self.rows: list[tuple[float, str, str, float, float, str]] = []
        #: the run's set-points (``ref.<output>`` → value), the loop's own dict once a run
        #: attaches it (:meth:`attach`)
        self.refs: dict[str, float] = {}
        self.t = math.nan
        self._catalog = self._declared()
        self._values = {name: s.start for name, s in self._catalog.items()}
        #: called after each sample with the desk (a faceplate publishes its status)
        self.listeners: list[Callable[[OperatorDesk], None]] = []
        #: the last sample's inputs the plant got and the controller computed, by input
        self.applied: dict[str, float] = {}
        self.computed: dict[str, float] = {}

    def _declared(self) -> dict[str, Setting]:
        """The controller's settings and the run's set-points, by name."""
        ctrl = self.controller
        out: dict[str, Setting] = {}
        if {Capability.SETTINGS, Capability.OPERATOR} & set(ctrl.capabilities):
            out.update(ctrl.settings())
        for s in ctrl.inputs:
            if s.name.startswith("ref."):
                y = s.name[len("ref."):]
                lo, hi = ctrl.bounds.get(y, (-math.inf, math.inf))
                out[s.name] = Setting(s.name, lo, hi, f"set-point of {y}", math.nan, s.unit,
                                      role="operator")
        return out

    @property
    def catalog(self) -> Mapping[str, Setting]:
        """What may be changed, by name."""
        return self._catalog

    def value(self, name: str) -> float:
        """A setting's value now (as last accepted), or a set-point's."""
        if name.startswith("ref."):
            return float(self.refs.get(name, math.nan))
        return float(self._values.get(name, math.nan))

    def attach(self, refs: dict[str, float]) -> None:
        """A run starts: its set-points (the loop's dict) and the settings' start values."""
        with self.lock:
            self.refs = refs
            self._values = {name: s.start for name, s in self._catalog.items()}
            self.rows.clear()

    def check(self, name: str, value: Any, role: str = "operator") -> tuple[str, bool]:
        """Why ``name`` = ``value`` is refused before the controller sees it (``""``: it
        is not) and whether for the role (``True``) or the value: an unknown name, a role
        that may not change it, a value that is not a number (``op.mode``: or a word of
        :data:`MODE_WORDS`) or outside the setting's range."""
        setting = self._catalog.get(name)
        if setting is None:
            return (f"no setting {name!r} (settings: {', '.join(self._catalog) or 'none'})",
                    False)
        if setting.role not in ROLES.get(role, ()):
            return (f"{name} is the {setting.role}'s to change, not the {role}'s", True)
        value = mode_words(value)
        try:
            number = float(value)
        except (TypeError, ValueError):
            return f"{name}: {value!r} is not a number", False
        if math.isnan(number) and name.startswith("op.manual."):
            return "", False
        unit = f" {setting.unit}" if setting.unit else ""
        if not (math.isfinite(number) and setting.low <= number <= setting.high):
            return (f"{name}: {number:g}{unit} is outside [{setting.low:g}, "
                    f"{setting.high:g}]{unit}", False)
        if name.startswith(SWITCHES) and number not in (0.0, 1.0):
            return f"{name}: {number:g} is not 1 or 0", False
        return "", False

    def act(self, t: float, who: str, name: str, value: Any,
            role: str = "operator") -> Answer:
        """Check, apply and record one action (module docstring); never raises for a
        refused one (the answer says why)."""
        with self.lock:
            old = self.value(name)
            why, denied = self.check(name, value, role)
            number = _number(mode_words(value))
            if why:
                return self._record(t, who, name, old, number, Answer(
                    False, why, old, old, denied))
            if name.startswith("ref."):
                self.refs[name] = number
                return self._record(t, who, name, old, number,
                                    Answer(True, f"{name} = {number:g}", old, number))
            try:
                text = self.controller.set(name, number)
            except CosimError as exc:
                return self._record(t, who, name, old, number,
                                    Answer(False, str(exc), old, old))
            self._values[name] = number
            return self._record(t, who, name, old, number, Answer(True, text, old, number))

    def _record(self, t: float, who: str, name: str, old: float, new: float,
                answer: Answer) -> Answer:
        result = "accepted" if answer.accepted else f"refused: {answer.text}"
        self.rows.append((float(t), who, name, old, new, result))
        return answer

    def sampled(self, t: float, applied: Mapping[str, float],
                computed: Mapping[str, float]) -> None:
        """After the loop's sample at ``t`` (the inputs the plant got, ``applied``, and the
        controller computed): the listeners (a faceplate's status)."""
        self.t = t
        self.applied, self.computed = dict(applied), dict(computed)
        for listener in list(self.listeners):
            listener(self)


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan
