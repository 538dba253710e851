"""Controllers for the fault tests of ``cosim run`` (``--controller tests.cosim.sleepy:<Class>``
from the repository root): the PI baseline made slow, or hung from some time on."""

from __future__ import annotations

import time

from controllers.pi import PIController


class SleepyPI(PIController):
    """The PI baseline that sleeps ``delay`` seconds in every step, and from ``hang_at``
    seconds of simulated time on sleeps ``hang`` seconds (a hung controller)."""

    def __init__(self, delay: float = 0.0, hang_at: float = float("inf"),
                 hang: float = 3600.0) -> None:
        super().__init__()
        self.delay, self.hang_at, self.hang = float(delay), float(hang_at), float(hang)

    def step(self, t: float, dt: float) -> None:
        time.sleep(self.hang if t >= self.hang_at else self.delay)
        super().step(t, dt)


class TimedPI(PIController):
    """The PI baseline with a wall-clock diagnostic (written to ``timings.csv``)."""

    timing_diagnostics = frozenset({"step_ms"})

    def step(self, t: float, dt: float) -> None:
        t0 = time.perf_counter()
        super().step(t, dt)
        self._step_ms = 1e3 * (time.perf_counter() - t0)

    def diagnostics(self) -> dict[str, float]:
        return {**super().diagnostics(), "step_ms": self._step_ms}
