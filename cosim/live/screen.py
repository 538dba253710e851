"""What a live run takes for a plausible measurement, beyond what OPC UA says of it.

A value whose status is Good and whose timestamp is recent may still be one no process can
have: a level of 1e30, a spike, a transmitter that froze while its server keeps stamping it
(open62541 stamps each read with the time of the read). The session refuses what the server
itself says is impossible (a value outside the node's EURange: :mod:`cosim.live.session`);
:class:`Screen` refuses what the problem declares so, per output or measured disturbance
(:class:`controllers.problem.Channel`):

==================  =========================================================================
``valid = [lo, hi]`` a value outside the range: "outside its valid range"
``rate = R``         (outputs) a change larger than ``R`` per sample since the last value
                     used (``R`` times the samples in between): "faster than its rate"
``frozen = N``       the same value, to the bit, for ``N`` samples in a row: "frozen"
==================  =========================================================================

A refused value makes the sample stale with that reason, as a Bad status does: the
controller is not stepped, the inputs hold, the watchdog counts it
(:class:`cosim.live.clock.WallClock`). :func:`reason_key` names the reason a summary counts
(the text before its parenthesis: ``"older than a sample (0.13 s)"`` counts as ``"older than
a sample"``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from cosim.core.pacing import Reading

__all__ = ["Screen", "reason_key"]


def reason_key(why: str) -> str:
    """The reason a stale signal is counted under (``why`` without its details)."""
    return why.split(" (", 1)[0]


class Screen:
    """The problem's plausibility checks of the measured ``channels`` (module docstring),
    sample by sample at the sample time ``Ts``."""

    def __init__(self, channels: Sequence[Any], Ts: float, outputs: Sequence[str]) -> None:
        self.Ts = float(Ts)
        self.units = {c.name: c.unit for c in channels}
        self.valid = {c.name: c.valid for c in channels if c.valid is not None}
        self.rate = {c.name: c.rate for c in channels
                     if c.rate is not None and c.name in outputs}
        self.frozen = {c.name: c.frozen for c in channels if c.frozen}
        self.last: dict[str, tuple[float, float]] = {}     # value used last, and its time
        self.same: dict[str, tuple[float, int]] = {}       # value, samples in a row

    @property
    def active(self) -> bool:
        """Whether the problem declares any check."""
        return bool(self.valid or self.rate or self.frozen)

    def __call__(self, reading: Reading, t: float) -> Reading:
        """``reading`` with the values the checks refuse made stale (in place)."""
        if not self.active:
            return reading
        stale = reading.stale
        for name, value in reading.values.items():
            why = stale.get(name) or self._why(name, value, t)
            if why and name not in stale:
                stale[name] = why
            elif not why and name in self.rate:
                self.last[name] = (value, t)
        return reading

    def _why(self, name: str, value: float, t: float) -> str:
        """Why ``value`` of ``name`` at ``t`` is not plausible ("" when it is); counts its
        repeats."""
        unit = self.units.get(name, "")
        n = self.frozen.get(name)
        if n:
            v0, count = self.same.get(name, (math.nan, 0))
            count = count + 1 if value == v0 else 1
            self.same[name] = (value, count)
            if count >= n:
                return f"frozen ({value:g} {unit} for {count} samples)"
        rng = self.valid.get(name)
        if rng is not None and not rng[0] <= value <= rng[1]:
            return f"outside its valid range ({value:g} not in [{rng[0]:g}, {rng[1]:g}] {unit})"
        rate, last = self.rate.get(name), self.last.get(name)
        if rate is not None and last is not None:
            samples = max(1, round((t - last[1]) / self.Ts))
            if abs(value - last[0]) > rate * samples:
                return (f"faster than its rate ({abs(value - last[0]):g} {unit} in {samples} "
                        f"samples > {rate:g} per sample)")
        return ""
