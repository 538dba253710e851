"""What an operator may do to a running loop from its page: the run's operator desk, seen
as the page's switches.

The page knows a run's switches only through its :class:`Operator`: the list of its
:class:`Action` objects (name, who may, the range, its value now) and one call,
:meth:`Operator.request`, that takes a value from a logged-in :class:`User` and answers
with a :class:`Reply`: accepted (and what was re-derived) or refused with the reason, the
setting unchanged. Requests are made from the run's loop thread, between two steps
(:class:`cosim.hmi.feed.Feed` queues them): the only place a component may be changed.

The :class:`Operator` of a run (:func:`operator_for`) is its master's operator desk
(:class:`cosim.core.operator.OperatorDesk`), the one checked entry that a scenario's
``op.*`` cells and the OPC UA faceplate go through too: its actions are the desk's catalog
(the set-points ``ref.<output>``, the operator's ``op.*`` settings of a controller that
declares them, the engineer's settings), a request is :meth:`~cosim.core.operator.
OperatorDesk.act` (the role, the range, the controller's own check), a set-point accepted
is the loop's from the next sample on, and every request, accepted or refused, is a row of
the desk's audit, the run's ``operator.csv`` (:data:`cosim.core.operator.AUDIT_COLUMNS`),
written with the run's other files.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from cosim.core.operator import ROLES, SWITCHES, OperatorDesk

__all__ = ["Action", "Operator", "Reply", "User", "operator_for"]


@dataclass(frozen=True)
class User:
    """A logged-in user: ``name`` and ``role`` (one of :data:`cosim.core.operator.ROLES`)."""

    name: str
    role: str

    def may(self, role: str) -> bool:
        """Whether this user may change what is ``role``'s to change (an engineer may
        change the operator's too)."""
        return role in ROLES.get(self.role, ())


@dataclass(frozen=True)
class Action:
    """One switch of the page.

    Attributes
    ----------
    name : str
        What it sets, the desk's name: ``ref.<output>`` (a set-point), ``op.<setting>``
        (the operator's: ``op.mode``, ``op.service.<input>``, ``op.min.<signal>``, ...), a
        controller setting's own name (the engineer's: ``R.qa``).
    label : str
        What the page shows.
    role : str
        Whose it is to change (:data:`cosim.core.operator.ROLES`).
    low, high : float
        The range of a number.
    choices : tuple of str
        The values of a switch (``("0", "1")``: the mode, 1 auto; an input in service; an
        output controlled); a number when empty.
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


class Operator:
    """A run's switches (module docstring): its operator desk's catalog. :meth:`request`
    is called from the loop's thread between two steps; :meth:`actions` from any thread.

    Parameters
    ----------
    desk : OperatorDesk
        The run's (:attr:`cosim.core.master.Master.desk`).
    """

    def __init__(self, desk: OperatorDesk) -> None:
        self.desk = desk

    @property
    def rows(self) -> Sequence[tuple[Any, ...]]:
        """The audit's rows so far (the desk's: ``operator.csv``'s)."""
        return self.desk.rows

    def actions(self) -> list[Action]:
        """The switches, with their values now."""
        desk, out = self.desk, []
        for name, s in desk.catalog.items():
            label = f"set-point {name[4:]}" if name.startswith("ref.") else name
            out.append(Action(name, label, s.role, s.low, s.high,
                              ("0", "1") if name.startswith(SWITCHES) else (), s.unit,
                              desk.value(name)))
        return out

    def request(self, action: str, value: float | str, user: User, t: float) -> Reply:
        """Set ``action`` to ``value`` for ``user`` before the sample at ``t``: checked (the
        role, the range, the controller's own check), applied from that sample on, or
        refused unchanged; audited either way."""
        answer = self.desk.act(t, user.name, action, value, user.role)
        return Reply(answer.accepted, answer.text)


def operator_for(master: Any) -> Operator:
    """The switches of the run of ``master`` (a :class:`~cosim.core.master.Master`): its
    operator desk's."""
    return Operator(master.desk)
