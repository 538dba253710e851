"""The wall clock of a run against a live plant, and its answer to every fault.

:class:`WallClock` is the pacer (:mod:`cosim.core.pacing`) of a live run: the run's loop is
the co-simulation's (:class:`cosim.core.loop.Run`), with the plant's I/O over OPC UA
(:class:`cosim.live.plant.LivePlant`). Each sample ``k`` (every ``period = Ts / speed``
seconds of the wall clock): wait for the sample's instant, read the outputs and measured
disturbances, step the controller, write the inputs, record the row. The clock locks its
phase to the plant's samples when the plant republishes its values every sample (as
``cosim serve-plant`` does): it reads just after the plant's new sample and writes before the
next one, so that the closed loop is the co-simulation master's (zero-order hold) to the bit.

What a live process does, and what the run does then (each counted in ``summary.json``'s
``live`` and marked in ``results.csv``'s ``live.*`` columns):

============================  ==============================================================
a measurement not fresh       (status not Good, source timestamp older than one sample, no
                              answer, disconnected): the controller is not stepped (its
                              observer does not advance) and nothing is written: the inputs
                              hold. ``live.fresh = 0``.
``watchdog`` such samples     the safe inputs (``safe = VALUE`` per input in the problem;
in a row                      without one an input holds its last value) are written and one
                              alarm line is given; the alarm clears, and control resumes, at
                              the next fresh sample. ``live.safe = 1``.
the connection drops          reads say "disconnected" (not fresh) while the session
                              reconnects with back-off; counted in ``reconnects``.
a step past its deadline      (inputs not computed within ``DEADLINE`` of the sample): they
                              are not written, the previous inputs stay. ``live.on_time = 0``.
Ctrl-C, SIGTERM, SIGHUP       the safe inputs are written, the session closed, the rows kept;
                              exit 130, 143, 129.
any write                     clipped to the input's box.
============================  ==============================================================

Latencies (read, compute, write) and lateness per sample go to ``timings.csv``; their
median and p99, the jitter (how late each read started) and the counts to the summary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core.pacing import Pacer, Reading
from cosim.core.scenario import DIST, PLANT

if TYPE_CHECKING:
    from cosim.core.loop import Run
    from cosim.live.plant import LivePlant

__all__ = ["DEADLINE", "LiveConfig", "WallClock", "refused_columns"]

#: The fraction of a sample within which the inputs must be written (the rest is the plant's
#: margin before its next sample).
DEADLINE = 0.8
#: How long after the plant's new sample the loop reads, as a fraction of the sample.
READ_LAG = 0.05


@dataclass
class LiveConfig:
    """How a live run runs: ``period`` [s of wall clock per sample], ``watchdog`` (stale
    samples in a row before the safe inputs; ``None``: never), the one-line ``notice``
    sink, and what the summary names (``endpoint``, ``security``, ``tags``, ``speed``)."""

    period: float
    watchdog: int | None = None
    notice: Callable[[str], None] = print
    describe: dict = field(default_factory=dict)


class WallClock(Pacer):
    """The pacer of a live run (module docstring) for the plant ``plant`` and the
    configuration ``cfg``."""

    own_prefixes = ("live",)

    def __init__(self, plant: LivePlant, cfg: LiveConfig) -> None:
        self.plant, self.cfg = plant, cfg
        self.counts = dict.fromkeys(("samples", "fresh", "stale", "deadline_misses",
                                     "watchdog_alarms", "safe_writes", "repeated"), 0)
        self.stale_run = 0
        self.reasons: dict[str, int] = {}
        self.lat: list[list[float]] = []     # time, read, compute, write, late [ms]
        self.locked = False
        self.last_source: float | None = None
        self.w0 = 0.0
        self._sample: dict[str, float] = {}

    # -- start ----------------------------------------------------------------------------
    def start(self, run: Run) -> None:
        """Lock onto the plant's samples: the instant of sample 0 is just after the plant's
        next new sample when its values are republished every sample (within 2.5 samples),
        else now."""
        P = self.cfg.period
        first = self.plant.read(0.0).source_time
        end = time.perf_counter() + 2.5 * P
        while first is not None and time.perf_counter() < end:
            time.sleep(min(P / 50, 0.01))
            ts = self.plant.read(0.0).source_time
            if ts is not None and ts != first:
                self.locked = True
                self.w0 = time.perf_counter() + READ_LAG * P
                return
        self.w0 = time.perf_counter()

    # -- each sample ------------------------------------------------------------------------
    def wait(self, k: int) -> None:
        """Until sample ``k``'s instant; its deadline for the inputs follows."""
        P = self.cfg.period
        due = self.w0 + k * P
        wait = due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        self.counts["samples"] += 1
        self._sample = {"due": due, "deadline": due + DEADLINE * P, "on_time": 0.0,
                        "written": 0.0, "safe": 0.0, "compute": math.nan,
                        "write": math.nan}

    def read(self, run: Run, t: float) -> Reading:
        """The plant's measurements; a repeat of the last sample (the plant's next one not
        out yet) is read again for up to a tenth of a sample."""
        s = self._sample
        s["r0"] = time.perf_counter()
        reading = self.plant.read(t)
        if self.locked and reading.fresh and reading.source_time == self.last_source:
            end = time.perf_counter() + 0.1 * self.cfg.period
            while reading.source_time == self.last_source and time.perf_counter() < end:
                time.sleep(self.cfg.period / 200)
                reading = self.plant.read(t)
            if reading.source_time == self.last_source:
                self.counts["repeated"] += 1
        self.last_source = reading.source_time
        s["r1"] = time.perf_counter()
        if reading.fresh:
            self._fresh(t)
        return reading

    def _fresh(self, t: float) -> None:
        self.counts["fresh"] += 1
        if self.cfg.watchdog is not None and self.stale_run >= self.cfg.watchdog:
            self.cfg.notice(f"alarm cleared at t = {t:g} s: fresh measurements, control "
                            "resumed")
        self.stale_run = 0

    def on_time(self) -> bool:
        """Whether the controller's inputs came within the sample's deadline."""
        s = self._sample
        s["r2"] = now = time.perf_counter()
        s["compute"] = now - s["r1"]
        if now <= s["deadline"]:
            s["on_time"] = 1.0
            return True
        self.counts["deadline_misses"] += 1
        return False

    def written(self, ok: bool) -> None:
        s = self._sample
        s["written"] = float(ok)
        s["write"] = time.perf_counter() - s["r2"]

    def stale(self, run: Run, t: float, reading: Reading) -> None:
        """Count the stale sample by reason, hold the inputs, and after ``watchdog`` such
        samples in a row write the safe inputs with one alarm line."""
        self.counts["stale"] += 1
        self.stale_run += 1
        for key in {why if not why.endswith(" s old") else "older than a sample"
                    for why in reading.stale.values()}:
            self.reasons[key] = self.reasons.get(key, 0) + 1   # samples, per reason
        run.diag = dict.fromkeys(run.diag, math.nan)
        if not run.u:
            run.u = dict.fromkeys(run.m.ctrl_outputs, math.nan)
        self._sample["safe"] = float(self._watchdog(run, t, reading))

    def _watchdog(self, run: Run, t: float, reading: Reading) -> bool:
        """After ``watchdog`` stale samples in a row: the safe inputs and one alarm line."""
        n = self.cfg.watchdog
        if n is None or self.stale_run != n:
            return False
        self.counts["watchdog_alarms"] += 1
        written = self.plant.write_safe()
        if written:
            self.counts["safe_writes"] += 1
            run.u = {**run.u, **written}
        units = {s.name: s.unit for s in self.plant.inputs}
        what = (", ".join(f"{k} = {v:g} {units[k]}" for k, v in written.items())
                if written else "none written (inputs hold their last values)")
        why = "; ".join(f"{s}: {w}" for s, w in list(reading.stale.items())[:3])
        self.cfg.notice(f"alarm at t = {t:g} s: no fresh measurement for {n} samples "
                        f"({why}); safe inputs: {what}")
        return bool(written)

    def sampled(self, run: Run, t: float, reading: Reading) -> None:
        """The sample's ``live.*`` columns and its latencies."""
        s = self._sample
        run.diag = {**run.diag, "live.fresh": float(reading.fresh), "live.on_time": s["on_time"],
                    "live.written": s["written"], "live.safe": s["safe"]}
        ms = 1e3
        self.lat.append([t, (s["r1"] - s["r0"]) * ms, s["compute"] * ms, s["write"] * ms,
                         (s["r0"] - s["due"]) * ms])

    # -- the end --------------------------------------------------------------------------------
    def finish(self, run: Run) -> None:
        """The live summary and the latencies (``timings.csv``), after the controller and
        the plant were wound up (the safe inputs written)."""
        result = run.result
        lat = np.array(self.lat, dtype=float).reshape(-1, 5)
        ctrl_rows = {row[0]: row[1:] for row in result.timing_rows}
        extra = result.timing_columns[1:]
        result.timing_columns = ["time", "live.read_ms", "live.compute_ms", "live.write_ms",
                                 "live.late_ms", *extra]
        result.timing_rows = [[*row, *ctrl_rows.get(row[0], [math.nan] * len(extra))]
                              for row in lat.tolist()]
        session = self.plant.session
        result.live = {
            **self.cfg.describe, "period_s": self.cfg.period, "phase_locked": self.locked,
            **self.counts, "stale_reasons": self.reasons,
            "reconnects": session.reconnects, "write_failures": self.plant.write_failures,
            "clipped": self.plant.clipped, "watchdog": self.cfg.watchdog,
            "jitter_ms": _stats(np.abs(lat[:, 4])),
            "latency_ms": {"read": _stats(lat[:, 1]), "compute": _stats(lat[:, 2]),
                           "write": _stats(lat[:, 3]),
                           "loop": _stats(lat[:, 1] + lat[:, 2] + lat[:, 3])},
        }


def refused_columns(scenario: Any) -> str | None:
    """The first scenario column a live plant cannot take (it sets the plant: ``plant.*``,
    ``dist.*``), or ``None``."""
    for col in (*scenario.columns_of(PLANT), *scenario.columns_of(DIST)):
        return col.name
    return None


def _stats(values: np.ndarray) -> dict[str, float | None]:
    """Median, p99 and max of the finite ``values`` (``None`` when there are none)."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return {"median": None, "p99": None, "max": None}
    return {"median": float(np.median(v)), "p99": float(np.percentile(v, 99)),
            "max": float(v.max())}
