"""What a run's loop meets the plant through: a plant I/O and a pacer.

One loop (:class:`cosim.core.loop.Run`) serves every plant. What differs between a plant FMU
stepped in simulated time and a process running on its own clock is behind two seams:

* the **plant I/O** (:class:`PlantIO`): read the measurements (with whether each is fresh),
  write the inputs, advance the plant over a sample. :class:`ComponentIO` is the I/O of any
  plant component the master steps (an FMU in process or in a worker, the GRU model as a
  plant): its reads are always fresh (a non-finite output fails the run), its writes always
  land, advancing steps it. A live plant (:class:`cosim.live.plant.LivePlant`, OPC UA)
  implements the protocol itself: reads may be stale, writes may fail, it advances on its own.
* the **pacer** (:class:`Pacer`): when each sample happens and what is done about time:
  simulated time (this class: as fast as the computer goes, nothing is late) or the wall
  clock (:class:`cosim.live.clock.WallClock`: a sample every ``Ts / speed`` seconds, a
  deadline for the inputs, stale samples held, a watchdog, the latencies).

A new fieldbus is one module implementing :class:`PlantIO`, registered in
:mod:`cosim.core.plants`; it runs with the wall-clock pacer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from cosim.core.errors import SimulationFailed

if TYPE_CHECKING:
    from cosim.core.component import Component
    from cosim.core.loop import Run

__all__ = ["ComponentIO", "Pacer", "PlantIO", "Reading"]


@dataclass
class Reading:
    """One read of the measured signals.

    Attributes
    ----------
    values : dict
        Each signal's value (NaN where none came).
    stale : dict
        Why a signal is not fresh (``"status BadSensorFailure"``, ``"3.2 s old"``,
        ``"disconnected"``), for those that are not; empty when all are fresh.
    source_time : float or None
        The newest source timestamp among them [s since the epoch] (a live plant's).
    """

    values: dict[str, float]
    stale: dict[str, str] = field(default_factory=dict)
    source_time: float | None = None

    @property
    def fresh(self) -> bool:
        """Whether every signal is fresh."""
        return not self.stale


class PlantIO(Protocol):
    """How the loop reads, writes and advances a plant (module docstring).

    Attributes
    ----------
    reads_disturbances : bool
        Its readings hold the measured disturbances too (a live plant's are measured, not
        set by the scenario).
    """

    reads_disturbances: bool

    def start_values(self, values: Mapping[str, float]) -> None:
        """The scenario's first values of plant inputs and disturbances, once set up."""
        ...

    def read(self, t: float) -> Reading:
        """The measurements at ``t``."""
        ...

    def write(self, values: Mapping[str, float]) -> bool:
        """The inputs to hold from now on; whether they reached the plant."""
        ...

    def advance(self, t: float, dt: float) -> None:
        """The plant from ``t`` to ``t + dt`` with the inputs held."""
        ...


class ComponentIO:
    """The I/O of a plant component the master steps (module docstring): reads are always
    fresh and must be finite, writes set its inputs, advancing steps it."""

    reads_disturbances = False

    def __init__(self, plant: Component) -> None:
        self.plant = plant
        self._names = [s.name for s in plant.outputs]
        self._reading = Reading({})   # reused: a read allocates nothing

    def start_values(self, values: Mapping[str, float]) -> None:
        given = {k: v for k, v in values.items() if not math.isnan(v)}
        if given:
            self.plant.set_inputs(given)

    def read(self, t: float) -> Reading:
        """The plant's outputs ``y(t)``; a non-finite one fails the run."""
        y = self.plant.get_outputs()
        if not all(map(math.isfinite, y.values())):
            bad = next(n for n in self._names if not math.isfinite(y[n]))
            raise SimulationFailed(f"plant output '{bad}' is {y[bad]!r} at t={t!r}")
        self._reading.values = y
        return self._reading

    def write(self, values: Mapping[str, float]) -> bool:
        self.plant.set_inputs(values)
        return True

    def advance(self, t: float, dt: float) -> None:
        self.plant.step(t, dt)


class Pacer:
    """Simulated time: every sample at once, nothing late, nothing stale (module
    docstring). A pacer's hooks, in the order the loop calls them each sample:
    :meth:`wait`, :meth:`read`, then :meth:`on_time` and :meth:`written` after a controller
    step, or :meth:`stale` for a stale reading, and :meth:`sampled` before the row is
    recorded; :meth:`start` after the set-up, :meth:`finish` at the end.

    Attributes
    ----------
    own_prefixes : tuple of str
        Diagnostics named ``<prefix>.<name>`` with one of these prefixes are the pacer's
        own columns, recorded under that name (the wall clock's ``live.fresh``).
    """

    own_prefixes: tuple[str, ...] = ()

    def start(self, run: Run) -> None:
        """After the plant and the controller are set up."""

    def wait(self, k: int) -> None:
        """Until sample ``k`` is due."""

    def read(self, run: Run, t: float) -> Reading:
        """The plant's measurements at sample ``t``."""
        return run.io.read(t)

    def on_time(self) -> bool:
        """After the controller's step: whether its inputs may still be written."""
        return True

    def written(self, ok: bool) -> None:
        """The inputs were written (``ok``: they reached the plant)."""

    def stale(self, run: Run, t: float, reading: Reading) -> None:
        """A reading that is not fresh: the controller was not stepped."""

    def sampled(self, run: Run, t: float, reading: Reading) -> None:
        """Before the sample's row is recorded (its own columns into ``run.diag``)."""

    def finish(self, run: Run) -> None:
        """After the run (its summary and timings into ``run.result``)."""

    def describe(self) -> dict[str, Any]:
        """What the run's summary says of the pacing (nothing in simulated time)."""
        return {}
