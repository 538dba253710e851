"""A live plant as the master sees it: the problem's signals, read and written over OPC UA.

:class:`LivePlant` is a :class:`~cosim.core.component.Component` whose outputs are the last
measurements read (:meth:`LivePlant.read`) and whose inputs are written to the plant
(:meth:`LivePlant.write`), never outside their box; it does not step (the plant runs on its
own clock). Its measured disturbances are read like its outputs. :meth:`LivePlant.terminate`
writes the safe inputs (once the run has written to the plant) and closes the session.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from cosim.core.component import Component, Signal
from cosim.live.session import PlantSession, Reading

__all__ = ["LivePlant"]


class LivePlant(Component):
    """The problem's plant behind an OPC UA session (see the module docstring).

    Parameters
    ----------
    problem : ControlProblem
        Inputs (written, with their boxes and ``safe`` values), outputs and measured
        disturbances (read).
    session : PlantSession
        Not yet connected (:meth:`setup` connects).

    Attributes
    ----------
    written : dict
        The last values written to each input.
    clipped : int
        Values the controller asked for outside their box (written at the box's edge).
    write_failures : int
        Writes that did not reach the plant.
    """

    name = "plant"
    fmi_version = "OPC UA"
    direct_feedthrough = False

    def __init__(self, problem: Any, session: PlantSession) -> None:
        self.problem, self.session = problem, session
        self.inputs = tuple(Signal(c.name, c.unit, c.description) for c in problem.inputs)
        self.outputs = tuple(Signal(c.name, c.unit, c.description) for c in problem.outputs)
        self.boxes = {c.name: (c.min, c.max) for c in problem.inputs}
        self.safe = {c.name: c.safe for c in problem.inputs if c.safe is not None}
        # the measured disturbances are read, not set: named here so that the master wires
        # them to the controller's dist.<d> inputs
        self.tunables = tuple(c.name for c in problem.disturbances)
        self.path = session.endpoint
        self.values: dict[str, float] = {s.name: math.nan for s in self.outputs}
        self.written: dict[str, float] = {}
        self.clipped = 0
        self.write_failures = 0

    @property
    def where(self) -> str:
        """Messages name the plant by its endpoint."""
        return str(self.path)

    def setup(self, t0: float) -> None:
        """Connect and find the tags (:meth:`PlantSession.connect`)."""
        self.session.connect()

    def read(self) -> Reading:
        """Read the outputs and disturbances; :meth:`get_outputs` returns them after."""
        reading = self.session.read()
        self.values = reading.values
        return reading

    def get_outputs(self) -> dict[str, float]:
        return self.values

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Not used by a live run (:meth:`write` is); writes like it."""
        self.write(values)

    def step(self, t: float, dt: float) -> None:
        """Nothing: a live plant runs on its own clock."""

    def write(self, values: Mapping[str, float]) -> bool:
        """Write the inputs among ``values``, each clipped to its box (a NaN is not
        written); ``False`` when the write did not reach the plant."""
        out = {}
        for name, value in values.items():
            box = self.boxes.get(name)
            if box is None or not math.isfinite(value):
                continue
            v = min(max(float(value), box[0]), box[1])
            if v != value:
                self.clipped += 1
            out[name] = v
        ok = self.session.write(out)
        if ok:
            self.written.update(out)
        elif out:
            self.write_failures += 1
        return ok

    def write_safe(self) -> dict[str, float]:
        """Write the inputs' safe values (inputs without one hold their last); the values
        written, empty when none are declared or the write failed."""
        if self.safe and self.write(self.safe):
            return dict(self.safe)
        return {}

    def terminate(self) -> None:
        """Write the safe inputs, when this run has written to the plant (one that never
        took control leaves it as it was), and close the session; safe to call twice."""
        if self.session.connected and self.written:
            self.write_safe()
        self.session.close()
