"""What a run records (:class:`RunResult`), where its rows go (:class:`RowSink`), and its
communication times: shared by the master (:mod:`cosim.core.master`) and its loop
(:mod:`cosim.core.loop`), which import this module and not each other's."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["COMPLETE", "DEGRADED_SHARE", "FAILING_SHARE", "MAX_STEPS", "PREFIX_CTRL",
           "PREFIX_DIST", "PREFIX_PLANT", "PREFIX_REF", "PREFIX_SENSOR", "RowSink", "RunResult",
           "RunWatcher", "communication_times", "shortfall_verdict"]

#: Column prefixes of recorded signals (results.csv).
PREFIX_REF, PREFIX_PLANT, PREFIX_SENSOR, PREFIX_CTRL = "ref", "plant", "sensor", "ctrl"
#: The measured disturbances' columns (set on the plant, measured by the controller).
PREFIX_DIST = "dist"


@dataclass
class RunResult:
    """Everything a run recorded, complete or up to a fault.

    Attributes
    ----------
    columns : list of str
        ``time`` then one name per recorded signal (see :func:`Master.columns`).
    rows : list of list of float
        One row per communication point reached.
    status : str
        ``"ok"``, ``"degraded"`` (it ran to its end, but its controller did not serve more
        than :data:`DEGRADED_SHARE` of the steps: :func:`shortfall_verdict`), ``"failed"``
        or ``"interrupted"``.
    reason : str
        Why the run failed or is degraded (empty when ok).
    steps : int
        Plant steps completed.
    steps_planned : int
        Plant steps the scenario asks for.
    live : dict
        A run against a live plant: what its loop saw (``summary.json``'s ``live``); empty
        otherwise.
    """

    columns: list[str]
    rows: list[list[float]]
    status: str = "ok"
    reason: str = ""
    steps: int = 0
    steps_planned: int = 0
    step_size: float = 0.0
    start_time: float = 0.0
    stop_time: float = 0.0
    outputs: list[str] = field(default_factory=list)
    references: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    perturbation_times: list[float] = field(default_factory=list)
    controller_summary: dict = field(default_factory=dict)
    live: dict = field(default_factory=dict)
    timing_columns: list[str] = field(default_factory=list)
    timing_rows: list[list[float]] = field(default_factory=list)
    #: the operator's actions (:mod:`cosim.core.operator`): ``operator.csv``'s rows
    operator_rows: list[tuple] = field(default_factory=list)
    wall_time_s: float = 0.0
    loop_time_s: float = 0.0
    error: BaseException | None = None


#: Most communication steps one run may take (results are held in memory).
MAX_STEPS = 1_000_000
#: A run whose controller did not serve more than this share of its steps (it fell back, its
#: problem had no answer: the controller summary's ``shortfall``) ends ``"degraded"``.
DEGRADED_SHARE = 0.1
#: ... more than this share: the command that ran it exits 1.
FAILING_SHARE = 0.5
#: The statuses of a run that ran to its end (its KPIs count in a campaign).
COMPLETE = ("ok", "degraded")


def shortfall_verdict(summary: dict) -> tuple[float, str] | None:
    """``(share, line)`` of a controller summary's ``shortfall`` (``steps`` not served ``of``
    how many, ``what`` it did instead, ``why``, ``first_time``), ``None`` without one: the
    share of steps not served and the line that says so."""
    short = summary.get("shortfall") if isinstance(summary, dict) else None
    if not isinstance(short, dict) or not short.get("of"):
        return None
    steps, of = int(short.get("steps", 0)), int(short["of"])
    share = steps / of
    why = f"; {short['why']}" if short.get("why") else ""
    first = short.get("first_time")
    when = f", first at t={first:g} s" if isinstance(first, int | float) else ""
    return share, (f"the controller {short.get('what', 'did not serve')} at {steps} of {of} "
                   f"steps ({100 * share:.0f} %{why}){when}")


def communication_times(t0: float, stop: float, dt: float) -> list[float]:
    """``t0, t0 + dt, ...`` up to ``stop``; a last, shorter step lands exactly on ``stop``."""
    n = math.floor((stop - t0) / dt + 1e-9)
    times = [t0 + k * dt for k in range(n + 1)]
    if stop - times[-1] > 1e-9 * dt:
        times.append(stop)
    else:
        times[-1] = stop
    return times


class RowSink(Protocol):
    """Where :meth:`Master.run` hands each recorded row (see ``record``)."""

    def append(self, row: list[float], columns: list[str]) -> None:
        """Take one row; ``columns`` names its cells (it grows when diagnostics appear)."""


class RunWatcher(RowSink, Protocol):
    """What follows a run from inside its loop (a live page of the run, :mod:`cosim.hmi`):
    shown the run's record before the first step, handed each row as a :class:`RowSink` is,
    and given a turn between two steps, where it may act on the run through the master's
    operator desk (:attr:`cosim.core.master.Master.desk`: its set-points are the loop's).
    Every call comes from the loop's thread, between the controller's steps (the only place
    a component may be asked anything), and returns at once; what the watcher raises ends
    the run as a sink's error does."""

    def start(self, result: RunResult) -> None:
        """Before the first step: the run's record, which grows as the run goes (its
        ``timing_rows``: the controller's wall-clock diagnostics, one row per step)."""

    def between(self, t: float) -> None:
        """Before the sample at ``t`` (and its scenario row): what the watcher does to the
        run, from that sample on."""
