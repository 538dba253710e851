"""The watchdog of a live run: a safe state that is reached, and said truthfully.

After ``limit`` samples in a row without a fresh measurement the watchdog raises one alarm
line and writes the problem's safe inputs (``safe = VALUE`` per input). A safe write is
done when the plant reads the safe values back (:meth:`cosim.live.plant.LivePlant.write_safe`);
until then it is tried again every stale sample (the link may be down just then), and once
reached the inputs are held there until a fresh sample clears the alarm (one line) and the
controller takes over again. The lines say which happened:

* ``alarm at t = 75 s: no fresh measurement for 3 samples (h1: disconnected); safe inputs
  qa = 0 m3/s, qb = 0 m3/s written``;
* ``...; safe inputs not yet written: link down, retrying``, then, once they are,
  ``safe inputs qa = 0 m3/s, qb = 0 m3/s written at t = 150 s (try 4)``;
* ``...; no safe inputs declared: inputs hold`` (an input without a safe value holds its
  last one: "qb holds" after the others).

:meth:`Watchdog.line` sums the alarms up for the run's last line.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from cosim.core.pacing import Reading

if TYPE_CHECKING:
    from cosim.live.plant import LivePlant

__all__ = ["Watchdog"]


class Watchdog:
    """The watchdog of ``plant`` (module docstring): ``limit`` stale samples in a row before
    the alarm (``None``: never), one-line messages to ``notice``.

    Attributes
    ----------
    alarms : int
        Alarms raised.
    safe_writes : int
        Samples at which a safe write reached the plant.
    tries : int
        Safe writes tried.
    outcomes : list of (float, str)
        Each alarm's time and what became of its safe inputs.
    """

    def __init__(self, plant: LivePlant, limit: int | None,
                 notice: Callable[[str], None]) -> None:
        self.plant, self.limit, self.notice = plant, limit, notice
        self.stale_run = 0
        self.alarms = self.safe_writes = self.tries = 0
        self.outcomes: list[tuple[float, str]] = []
        self._reached = False
        self._tries_now = 0

    @property
    def alarmed(self) -> bool:
        """Whether an alarm is raised now."""
        return self.limit is not None and self.stale_run >= self.limit

    def fresh(self, t: float) -> None:
        """A fresh sample: the alarm, if any, clears (one line)."""
        if self.alarmed:
            self.notice(f"alarm cleared at t = {t:g} s: fresh measurements, control resumed")
        self.stale_run = 0

    def stale(self, t: float, reading: Reading) -> dict[str, float]:
        """A stale sample: the alarm when it is the ``limit``-th in a row, a safe write
        while the safe state is not reached; the safe values written at this sample."""
        self.stale_run += 1
        if not self.alarmed:
            return {}
        first = self.stale_run == self.limit
        if first:
            self.alarms += 1
            self._reached, self._tries_now = False, 0
        if self._reached or not self.plant.safe:
            if first:
                self._said(t, reading, "no safe inputs declared: inputs hold")
            return {}
        self.tries += 1
        self._tries_now += 1
        written, why = self.plant.write_safe()
        if written:
            self.safe_writes += 1
        self._reached = not why
        if first:
            self._said(t, reading, self._what(written) if not why
                       else f"safe inputs not yet written: {why}, retrying")
        elif not why:
            self.notice(f"{self._what(written)} at t = {t:g} s (try {self._tries_now})")
            self.outcomes[-1] = (self.outcomes[-1][0], f"{self._what(written)} at t = {t:g} s")
        return written

    def _what(self, written: dict[str, float]) -> str:
        units = {s.name: s.unit for s in self.plant.inputs}
        text = ", ".join(f"{k} = {v:g} {units[k]}" for k, v in written.items())
        held = [s.name for s in self.plant.inputs if s.name not in written]
        return f"safe inputs {text} written" + (f" ({', '.join(held)} holds)" if held else "")

    def _said(self, t: float, reading: Reading, what: str) -> None:
        """The alarm line, and what it said for :meth:`line`."""
        why = "; ".join(f"{s}: {w}" for s, w in list(reading.stale.items())[:3])
        self.notice(f"alarm at t = {t:g} s: no fresh measurement for {self.limit} samples "
                    f"({why}); {what}")
        self.outcomes.append((t, what.removesuffix(", retrying").replace(
            "not yet written", "never written")))

    def line(self) -> str:
        """The alarms in a few words (``""`` when none was raised), for the last line."""
        if not self.alarms:
            return ""
        shown = "; ".join(f"at t = {t:g} s: {what}" for t, what in self.outcomes[:3])
        more = f"; {self.alarms - 3} more" if self.alarms > 3 else ""
        s = "s" if self.alarms > 1 else ""
        return f"{self.alarms} watchdog alarm{s} ({shown}{more})"
