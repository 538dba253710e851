"""What a run's page shows, as the run goes or after it: its :class:`Layout` and its
:class:`Feed`.

A :class:`Feed` is the one place the page reads from. During a run it is the run's
:class:`~cosim.core.run_result.RunWatcher` (:meth:`cosim.core.master.Master.run`'s
``watch``): from the loop's thread it keeps each row (a reference, not a copy), the
controller's plan (:attr:`~cosim.core.component.Capability.PREDICTION`, read a few times a
second) and the one-step prediction error of each plan read (the next sample's measured
outputs against it), and between two steps it answers the page's requests through the run's
:class:`~cosim.hmi.actions.Operator` (the run's operator desk, which audits them). The
page's sessions read it from the server's thread: nothing there touches the controller.
After a run (:func:`cosim.hmi.replay.load`) it holds the finished run's rows and operator
actions, read from its folder.

The loop's share is a list append and a clock read per row, and the controller's plan read
a few times a second (:data:`PLAN_EVERY_S`): what the page costs the run's step time is
measured by ``benchmarks/bench_hmi.py``.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from cosim.core.component import Capability, Component, Prediction
from cosim.core.run_result import RunResult
from cosim.hmi.actions import Action, Operator, Reply, User

__all__ = ["ACTIONS_S", "PLAN_EVERY_S", "Feed", "Layout", "SignalInfo"]

#: How often the switches' values are read again during a run [s].
ACTIONS_S = 0.5
#: How often the controller's plan is read during a run [s of the wall clock].
PLAN_EVERY_S = 0.2


@dataclass(frozen=True)
class SignalInfo:
    """A controlled output or an input as the page shows it: its name, unit and box
    (``nan`` where it has none)."""

    name: str
    unit: str = ""
    low: float = math.nan
    high: float = math.nan


@dataclass
class Layout:
    """What the page shows of a run, known before its first row.

    Attributes
    ----------
    title : str
        The scenario (and the controller).
    outputs, inputs : list of SignalInfo
        The controlled outputs (set-points ``ref.<name>`` where they have one), then the
        inputs.
    live : bool
        A run against a live plant (its ``live.*`` columns).
    certificate : str
        The controller's grade: ``"certified"``, why it runs uncertified, or ``""`` (none).
    timing : list of str
        The names of the controller's wall-clock diagnostics (``timings.csv``'s columns
        after ``time``).
    """

    title: str
    outputs: list[SignalInfo]
    inputs: list[SignalInfo]
    step: float
    start_time: float
    stop_time: float
    live: bool = False
    certificate: str = ""
    timing: list[str] = field(default_factory=list)

    @staticmethod
    def of_run(master: Any, meta: Mapping[str, Any]) -> Layout:
        """The layout of a run about to start (a :class:`~cosim.core.master.Master`)."""
        ctrl = master.controller
        units = {s.name: s.unit for s in (*ctrl.inputs, *ctrl.outputs) if s.unit}
        bounds = dict(ctrl.bounds)

        def info(name: str) -> SignalInfo:
            lo, hi = bounds.get(name, (math.nan, math.nan))
            return SignalInfo(name, units.get(name, ""), float(lo), float(hi))

        outputs = list(dict.fromkeys([*master.refs, *master.measured]))
        grade = ""
        if Capability.NOTICE in ctrl.capabilities:
            grade = ctrl.notice or "certified"
        sc = master.scenario
        return Layout(title=f"{sc.path.name} · {meta.get('controller', ctrl.name)}",
                      outputs=[info(o) for o in outputs],
                      inputs=[info(u) for u in master.ctrl_outputs],
                      step=float(master.dt), start_time=float(sc.start_time),
                      stop_time=float(sc.stop_time), live=bool(master.pacer.own_prefixes),
                      certificate=grade, timing=sorted(ctrl.timing_diagnostics))


class Feed:
    """A run's page data (module docstring); a :class:`~cosim.core.run_result.RunWatcher`.

    Parameters
    ----------
    layout : Layout
    controller : Component, optional
        The run's controller (its plan is read after each row when it declares one);
        ``None`` for a finished run.
    operator : Operator, optional
        The run's switches (``None``: none, a finished run).
    audit : sequence of tuple, optional
        The operator's actions (``operator.csv``'s rows): a finished run's; default the
        operator's audit, as it grows (none without an operator).
    plan_every : float
        Seconds of the wall clock between two reads of the controller's plan (0: every
        row); the prediction error is that of the plans read, one sample ahead.
    """

    def __init__(self, layout: Layout, controller: Component | None = None,
                 operator: Operator | None = None,
                 audit: Sequence[tuple[Any, ...]] | None = None,
                 plan_every: float = PLAN_EVERY_S) -> None:
        self.layout = layout
        self.plan_every = float(plan_every)
        self.ctrl = controller
        self.operator = operator
        self.audit: Sequence[tuple[Any, ...]] = (
            audit if audit is not None else operator.rows if operator is not None else [])
        self.rows: list[list[float]] = []
        self.columns: list[str] = []
        self.index: dict[str, int] = {}
        #: the controller's wall-clock diagnostics per step (the run's ``timing_rows``)
        self.timing_rows: list[list[float]] = []
        #: the wall time [s] between one row and the next (the loop's step)
        self.loop_s: deque[float] = deque(maxlen=64)
        #: the last plan: ``(time, Prediction)``
        self.prediction: tuple[float, Prediction] | None = None
        #: one-step prediction errors: ``(time, {output: measured − predicted})``
        self.errors: list[tuple[float, dict[str, float]]] = []
        #: ``"running"``, then the run's status; why it ended so
        self.status, self.reason = "running", ""
        #: the switches with their values now (read in the loop's thread)
        self.actions: list[Action] = []
        self._requests: deque[tuple[int, str, Any, User]] = deque()
        self.replies: dict[int, Reply] = {}
        self._tickets = itertools.count(1)
        self._plans = controller is not None and Capability.PREDICTION in controller.capabilities
        self._last = math.nan
        self._actions_at = self._plan_at = -math.inf
        self.ended = threading.Event()

    # -- the run's side (its loop's thread) -----------------------------------------------
    def start(self, result: RunResult) -> None:
        """Before the first step: the run's timing rows, and the switches' values."""
        self.timing_rows = result.timing_rows
        if self.operator is not None:
            self.actions = self.operator.actions()

    def append(self, row: list[float], columns: list[str]) -> None:
        """One row: kept and timed; the one-step error of the last plan when this row is
        the sample it predicted; a new plan every :attr:`plan_every` seconds."""
        now = time.perf_counter()
        if self.rows:
            self.loop_s.append(now - self._last)
        self._last = now
        if len(columns) != len(self.columns):
            self.columns = list(columns)
            self.index = {c: i for i, c in enumerate(columns)}
        self.rows.append(row)
        if not self._plans:
            return
        last = self.prediction
        if last is not None and abs(row[0] - last[0] - last[1].step) <= 1e-9 * max(
                1.0, abs(row[0])):
            self._error(row, last[1])
        if now - self._plan_at >= self.plan_every:
            self._plan_at = now
            self._plan(row)

    def _error(self, row: list[float], plan: Prediction) -> None:
        """The measured outputs of ``row`` against what ``plan`` predicted for them."""
        index, errors = self.index, {}
        for o, values in plan.outputs.items():
            j = index.get(f"plant.{o}")
            if j is not None and len(values) > 1:
                errors[o] = row[j] - values[1]
        self.errors.append((row[0], errors))

    def _plan(self, row: list[float]) -> None:
        """The controller's plan at this row."""
        try:
            plan = self.ctrl.prediction()  # type: ignore[union-attr]
        except Exception as exc:   # the page must not end the run: it stops asking
            self._plans, self.reason = False, f"the controller's plan: {exc}"
            return
        last = self.prediction
        if plan is not None and (last is None or plan != last[1]):   # a new step's plan
            self.prediction = (row[0], plan)

    def between(self, t: float) -> None:
        """The page's requests, answered (and audited) by the operator from the sample at
        ``t`` on. The switches' values are read again every :data:`ACTIONS_S` seconds."""
        operator = self.operator
        if operator is None:
            return
        if not self._requests:
            now = time.monotonic()
            if now - self._actions_at >= ACTIONS_S:
                self.actions, self._actions_at = operator.actions(), now
            return
        while self._requests:
            ticket, action, value, user = self._requests.popleft()
            self.replies[ticket] = operator.request(action, value, user, t)
        self.actions = operator.actions()

    # -- the page's side (the server's thread) --------------------------------------------
    def request(self, action: str, value: float | str, user: User) -> int:
        """Queue a request for the next step; its ticket (:attr:`replies` holds the answer
        once the loop has given it)."""
        ticket = next(self._tickets)
        if self.status != "running":
            self.replies[ticket] = Reply(False, f"the run has ended ({self.status})")
        else:
            self._requests.append((ticket, action, value, user))
        return ticket

    def finish(self, status: str, reason: str = "") -> None:
        """The run has ended: its status; requests still waiting are refused."""
        self.status, self.reason = status, reason or self.reason
        while self._requests:
            ticket = self._requests.popleft()[0]
            self.replies[ticket] = Reply(False, f"the run has ended ({status})")
        self.ended.set()

    # -- reading ------------------------------------------------------------------------------
    def column(self, name: str) -> int | None:
        """The index of a column in the rows (``None``: the run has none)."""
        return self.index.get(name)

    def last(self, name: str) -> float:
        """The last row's value of column ``name`` (``nan`` before the first row)."""
        rows = self.rows
        return self.value(rows[-1], name) if rows else math.nan

    def value(self, row: Sequence[float], name: str) -> float:
        """A row's value of column ``name`` (``nan`` where it has none)."""
        j = self.index.get(name)
        return float(row[j]) if j is not None and j < len(row) else math.nan
