"""A campaign's operator events (``[operator]``): drawn like disturbances, each run its own, so
that a controller is qualified on what operators do to it (issue 61; docs:
guide/campaigns.md, guide/operating.md)::

    [operator]
    count = 2                        # events per run
    duration = [250.0, 1000.0]       # each lasts so long (seconds, drawn uniformly)
    service = ["qa", "qb"]           # an input out of service for the event
    "max.h1" = [1.0, 1.4]            # an operator limit narrowed: op.max.h1 drawn in the range

Each event draws its start (uniformly over the run, the first hold excluded: the controller
has settled), its kind (uniformly among the inputs of ``service`` and the limits named) and
its value, and becomes two ``op.*`` changes of the run's scenario: the setting at the start,
the default back at the end (in service; the engineer's box, the limit's end of it).
:func:`parse` reads the table (``file:line`` errors, exit 2), :func:`draw` draws one run's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.campaign.spec_values import Locator, finite, number

__all__ = ["OperatorSpec", "draw", "parse"]


@dataclass(frozen=True)
class OperatorSpec:
    """``[operator]`` (module docstring): ``count`` events of ``duration`` (low, high)
    seconds, each an input of ``service`` out of service or a limit of ``limits``
    (``"max.h1"`` → its range) narrowed."""

    count: int
    duration: tuple[float, float]
    service: tuple[str, ...] = ()
    limits: tuple[tuple[str, tuple[float, float]], ...] = ()

    @property
    def kinds(self) -> list[str]:
        """The settings an event may change: ``op.service.<input>``, ``op.<min|max>.<s>``."""
        return ([f"op.service.{u}" for u in self.service]
                + [f"op.{name}" for name, _ in self.limits])


def parse(table: Any, loc: Locator) -> OperatorSpec:
    """The ``[operator]`` table, checked (module docstring)."""
    if not isinstance(table, dict):
        raise loc.error("[operator] must be a table", "operator")
    count = int(number(table.get("count", 1), loc, "operator", "count", integer=True,
                       positive=True))
    span = table.get("duration")
    if (not isinstance(span, list) or len(span) != 2 or not all(finite(v) for v in span)
            or not 0 < span[0] <= span[1]):
        raise loc.error(f"[operator] duration = {span!r}: expected [low, high] seconds, "
                        "0 < low <= high", "operator", "duration")
    service = table.get("service", [])
    if not isinstance(service, list) or not all(isinstance(s, str) and s for s in service):
        raise loc.error(f"[operator] service = {service!r}: expected a list of input names",
                        "operator", "service")
    limits = []
    for key, value in table.items():
        if key in ("count", "duration", "service"):
            continue
        family, _, signal = key.partition(".")
        if family not in ("min", "max") or not signal:
            raise loc.error(f"[operator] {key}: expected count, duration, service or a limit "
                            "\"max.<signal>\" / \"min.<signal>\" = [low, high]", "operator",
                            key)
        if (not isinstance(value, list) or len(value) != 2
                or not all(finite(v) for v in value) or value[0] > value[1]):
            raise loc.error(f"[operator] {key} = {value!r}: expected a range [low, high] "
                            "(problem units)", "operator", key)
        limits.append((key, (float(value[0]), float(value[1]))))
    if not service and not limits:
        raise loc.error("[operator]: no events: give service = [...] or a limit range",
                        "operator")
    return OperatorSpec(count, (float(span[0]), float(span[1])), tuple(service),
                        tuple(limits))


def draw(spec: OperatorSpec, rng: np.random.Generator, start: float, stop: float,
         settle: float, boxes: dict[str, tuple[float, float]]
         ) -> list[tuple[float, dict[str, float]]]:
    """One run's events as scenario changes ``(time, {op.<setting>: value})``, in time
    order: each from a start drawn in ``[start + settle, stop)`` to its end (at most
    ``stop``); ``boxes``: the engineer's box of each signal (a limit's value at the end)."""
    kinds = spec.kinds
    out: list[tuple[float, dict[str, float]]] = []
    for _ in range(spec.count):
        t0 = float(rng.uniform(min(start + settle, stop), stop))
        length = float(rng.uniform(*spec.duration))
        kind = kinds[int(rng.integers(len(kinds)))]
        if kind.startswith("op.service."):
            on, off = 0.0, 1.0
        else:
            family, signal = kind.split(".")[1:]
            lo, hi = dict(spec.limits)[f"{family}.{signal}"]
            on = float(rng.uniform(lo, hi))
            off = boxes[signal][0 if family == "min" else 1]
        out.append((t0, {kind: on}))
        if t0 + length < stop:
            out.append((t0 + length, {kind: off}))
    return sorted(out, key=lambda change: change[0])
