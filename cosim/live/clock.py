"""The wall clock of a run against a live plant, and its answer to every fault.

:class:`WallClock` is the pacer (:mod:`cosim.core.pacing`) of a live run: the run's loop is
the co-simulation's (:class:`cosim.core.loop.Run`), with the plant's I/O over OPC UA
(:class:`cosim.live.plant.LivePlant`). Each sample ``k`` (every ``period = Ts / speed``
seconds of the wall clock): wait for the sample's instant, read the outputs and measured
disturbances, step the controller, write the inputs (and the heartbeat), record the row. The
clock locks its phase to the plant's samples when the plant republishes its values every
sample (as ``cosim serve-plant`` does): it reads just after the plant's new sample and writes
before the next one, so that the closed loop is the co-simulation master's (zero-order hold)
to the bit.

What a live process does, and what the run does then (each counted in ``summary.json``'s
``live`` and marked in ``results.csv``'s ``live.*`` columns):

============================  ==============================================================
a measurement not fresh       (status not Good, source timestamp older than one sample or
                              more than one in the future, not finite, outside its node's
                              EURange or the problem's ``valid`` range, faster than its
                              ``rate``, ``frozen``, no answer, disconnected): the controller
                              is not stepped (its observer does not advance) and nothing is
                              written: the inputs hold. ``live.fresh = 0``.
``watchdog`` such samples     one alarm line, and the safe inputs (``safe = VALUE`` per input
in a row                      in the problem) written and read back, again each sample until
                              they are (:mod:`cosim.live.watchdog`); the alarm clears, and
                              control resumes, at the next fresh sample. ``live.safe = 1``
                              where a safe write reached the plant.
the connection drops          reads say "disconnected" (not fresh) while the session
                              reconnects with back-off; counted in ``reconnects``.
a step past its deadline      (inputs not computed within ``DEADLINE`` of the sample): they
                              are not written, the previous inputs stay. ``live.on_time = 0``.
a write a node refuses        the other inputs are written; counted per input (``refused``).
Ctrl-C, SIGTERM, SIGHUP       the safe inputs are written, the session closed, the rows kept;
                              exit 130, 143, 129.
any write                     clipped to the input's box.
the run's end                 a run that never wrote an input, or whose controller computed
                              the inputs written from fresh data at less than
                              ``min_controlled`` of its samples, did not control the plant:
                              status "failed" (never wrote) or "degraded", and the command
                              exits 1 (:meth:`WallClock.finish`).
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

from cosim.core.errors import SimulationFailed
from cosim.core.pacing import Pacer, Reading
from cosim.core.run_result import COMPLETE
from cosim.core.scenario import DIST, PLANT
from cosim.live.screen import reason_key
from cosim.live.watchdog import Watchdog

if TYPE_CHECKING:
    from cosim.core.loop import Run
    from cosim.live.plant import LivePlant

__all__ = ["DEADLINE", "READ_LAG", "REPEAT_WAIT", "LiveConfig", "WallClock",
           "refused_columns"]

#: The fraction of a sample within which the inputs must be written (the rest is the plant's
#: margin before its next sample).
DEADLINE = 0.8
#: How long after the plant's new sample the loop reads, as a fraction of the sample.
READ_LAG = 0.05
#: How long a read that finds the last sample's values again is repeated, as a fraction of
#: the sample (the plant's next sample is late).
REPEAT_WAIT = 0.25


@dataclass
class LiveConfig:
    """How a live run runs: ``period`` [s of wall clock per sample], ``watchdog`` (stale
    samples in a row before the safe inputs; ``None``: never), the one-line ``notice``
    sink, the least share of controlled samples (``min_controlled``) and what the summary
    names (``endpoint``, ``security``, ``tags``, ``speed``, ``heartbeat``)."""

    period: float
    watchdog: int | None = None
    notice: Callable[[str], None] = print
    min_controlled: float = 0.5
    describe: dict = field(default_factory=dict)


class WallClock(Pacer):
    """The pacer of a live run (module docstring) for the plant ``plant`` and the
    configuration ``cfg``."""

    own_prefixes = ("live",)

    def __init__(self, plant: LivePlant, cfg: LiveConfig) -> None:
        self.plant, self.cfg = plant, cfg
        self.counts = dict.fromkeys(("samples", "fresh", "stale", "deadline_misses",
                                     "written", "controlled", "repeated"), 0)
        self.reasons: dict[str, int] = {}
        self.watchdog = Watchdog(plant, cfg.watchdog, cfg.notice)
        self.lat: list[list[float]] = []     # time, read, compute, write, late [ms]
        self.locked = False
        self.last_source: float | None = None
        self.w0 = 0.0
        self._sample: dict[str, float] = {}

    # -- start ----------------------------------------------------------------------------
    def start(self, run: Run) -> None:
        """Once connected, before the first write: one warning line when the problem
        declares no safe input value; then lock onto the plant's samples: the instant of
        sample 0 is just after the plant's next new sample when its values are republished
        every sample (within 2.5 samples), else now."""
        problem = self.plant.problem
        if not self.plant.safe:
            self.cfg.notice(f"warning: the problem {problem.source or problem.name} declares "
                            "no safe input value (safe = VALUE in [inputs.NAME]): the "
                            "watchdog and the run's end leave the plant's inputs as they are")
        P = self.cfg.period
        session = self.plant.session
        first = self.plant.read(0.0).source_time
        end = time.perf_counter() + 2.5 * P
        while first is not None and time.perf_counter() < end:
            session.idle(time.perf_counter() + min(P / 50, 0.01))
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
        self.plant.session.idle(due)     # the connection lives meanwhile
        self.counts["samples"] += 1
        self.plant.begin_sample(k)
        self._sample = {"due": due, "deadline": due + DEADLINE * P, "on_time": 0.0,
                        "written": 0.0, "safe": 0.0, "compute": math.nan,
                        "write": math.nan}

    def read(self, run: Run, t: float) -> Reading:
        """The plant's measurements, screened (:mod:`cosim.live.screen`); a repeat of the
        last sample (the plant's next one not out yet: a loaded plant's tick is late) is
        read again for up to :data:`REPEAT_WAIT` of a sample."""
        s = self._sample
        s["r0"] = time.perf_counter()
        reading = self.plant.read(t)
        last = self.last_source
        if self.locked and last is not None and reading.source_time == last:
            end = time.perf_counter() + REPEAT_WAIT * self.cfg.period
            while reading.source_time == last and time.perf_counter() < end:
                self.plant.session.idle(time.perf_counter() + self.cfg.period / 200)
                reading = self.plant.read(t)
            if reading.source_time == last:
                self.counts["repeated"] += 1
        if reading.source_time is not None:
            self.last_source = reading.source_time
        s["r1"] = time.perf_counter()
        reading = self.plant.screen(reading, t)
        if reading.fresh:
            self.counts["fresh"] += 1
            self.watchdog.fresh(t)
        return reading

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
        if ok:
            self.counts["controlled"] += 1
        if self.plant.reached:
            self.counts["written"] += 1

    def stale(self, run: Run, t: float, reading: Reading) -> None:
        """Count the stale sample by reason, hold the inputs, and let the watchdog answer
        (:mod:`cosim.live.watchdog`)."""
        self.counts["stale"] += 1
        for key in {reason_key(why) for why in reading.stale.values()}:
            self.reasons[key] = self.reasons.get(key, 0) + 1   # samples, per reason
        run.diag = dict.fromkeys(run.diag, math.nan)
        if not run.u:
            run.u = dict.fromkeys(run.m.ctrl_outputs, math.nan)
        written = self.watchdog.stale(t, reading)
        if written:
            run.u = {**run.u, **written}
            self._sample["safe"] = 1.0

    def sampled(self, run: Run, t: float, reading: Reading) -> None:
        """The sample's heartbeat (when no write carried it), its ``live.*`` columns and its
        latencies."""
        self.plant.end_sample()
        s = self._sample
        run.diag = {**run.diag, "live.fresh": float(reading.fresh), "live.on_time": s["on_time"],
                    "live.written": s["written"], "live.safe": s["safe"]}
        ms = 1e3
        self.lat.append([t, (s["r1"] - s["r0"]) * ms, s["compute"] * ms, s["write"] * ms,
                         (s["r0"] - s["due"]) * ms])

    # -- the end --------------------------------------------------------------------------------
    def finish(self, run: Run) -> None:
        """The live summary and the latencies (``timings.csv``), after the controller and
        the plant were wound up (the safe inputs written), and the run's verdict: one that
        did not control the plant is not "ok" (:meth:`_verdict`)."""
        result = run.result
        lat = np.array(self.lat, dtype=float).reshape(-1, 5)
        ctrl_rows = {row[0]: row[1:] for row in result.timing_rows}
        extra = result.timing_columns[1:]
        result.timing_columns = ["time", "live.read_ms", "live.compute_ms", "live.write_ms",
                                 "live.late_ms", *extra]
        result.timing_rows = [[*row, *ctrl_rows.get(row[0], [math.nan] * len(extra))]
                              for row in lat.tolist()]
        plant, dog = self.plant, self.watchdog
        result.live = {
            **self.cfg.describe, "period_s": self.cfg.period, "phase_locked": self.locked,
            **self.counts, "stale_reasons": self.reasons,
            "min_controlled": self.cfg.min_controlled,
            "watchdog": self.cfg.watchdog, "watchdog_alarms": dog.alarms,
            "safe_writes": dog.safe_writes, "safe_tries": dog.tries, "alarms": dog.line(),
            "at_end": plant.end, "reconnects": plant.session.reconnects,
            "write_failures": plant.write_failures, "refused": plant.refused,
            "heartbeats": plant.heartbeats, "clipped": plant.clipped,
            "nodes": {n: node.summary() for n, node in plant.session.nodes.items()},
            "jitter_ms": _stats(np.abs(lat[:, 4])),
            "latency_ms": {"read": _stats(lat[:, 1]), "compute": _stats(lat[:, 2]),
                           "write": _stats(lat[:, 3]),
                           "loop": _stats(lat[:, 1] + lat[:, 2] + lat[:, 3])},
        }
        self._verdict(result)

    def _verdict(self, result: Any) -> None:
        """A run that ran to its end but never wrote an input ("failed") or whose controller
        computed the inputs written from fresh data at less than ``min_controlled`` of its
        samples ("degraded", ``live["failing"]``): its status and the line that says so."""
        c, lv = self.counts, result.live
        n = max(c["samples"], 1)
        share = c["controlled"] / n
        lv["failing"] = False
        if result.status not in COMPLETE or (c["written"] and share >= self.cfg.min_controlled):
            return
        reasons = ", ".join(f"{k}: {v}" for k, v in sorted(self.reasons.items(),
                                                            key=lambda kv: -kv[1])[:3])
        why = (f"{c['stale']} stale ({reasons}), " if c["stale"] else "") + \
            f"{c['deadline_misses']} deadline misses, {lv['write_failures']} failed writes"
        alarms = f"; {lv['alarms']}" if lv["alarms"] else ""
        if not c["written"]:
            text = (f"the run never controlled the plant: no input written in {c['samples']} "
                    f"samples ({c['fresh']} fresh; {why}){alarms}")
            result.status, result.reason = "failed", text
            result.error = SimulationFailed(text)
        else:
            text = (f"the controller computed the inputs written from fresh data at "
                    f"{c['controlled']} of {c['samples']} samples ({100 * share:.0f} % < "
                    f"--min-controlled {100 * self.cfg.min_controlled:.0f} %; {why}){alarms}")
            result.status, result.reason = "degraded", text
        lv["failing"] = True


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
