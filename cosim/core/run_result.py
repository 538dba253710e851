"""What a run records (:class:`RunResult`), where its rows go (:class:`RowSink`), and its
communication times: shared by the master (:mod:`cosim.core.master`) and its loop
(:mod:`cosim.core.loop`), which import this module and not each other's."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["MAX_STEPS", "PREFIX_CTRL", "PREFIX_DIST", "PREFIX_PLANT", "PREFIX_REF",
           "PREFIX_SENSOR",
           "RowSink", "RunResult", "communication_times"]

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
        ``"ok"``, ``"failed"`` or ``"interrupted"``.
    reason : str
        Why the run failed (empty when ok).
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
    wall_time_s: float = 0.0
    loop_time_s: float = 0.0
    error: BaseException | None = None


#: Most communication steps one run may take (results are held in memory).
MAX_STEPS = 1_000_000


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
