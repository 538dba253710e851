"""A live plant as the master sees it: the problem's signals, read and written over OPC UA.

:class:`LivePlant` is a :class:`~cosim.core.component.Component` (its signals, for the
wiring) and the run's plant I/O (:class:`cosim.core.pacing.PlantIO`): its readings are the
measurements read over OPC UA, fresh or not (:meth:`LivePlant.read`), its inputs are written
to the plant (:meth:`LivePlant.write`), never outside their box, and it does not advance (the
plant runs on its own clock). Its measured disturbances are read like its outputs.
:meth:`LivePlant.terminate` writes the safe inputs (once the run has written to the plant)
and closes the session.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from cosim.core.component import Component, Signal
from cosim.core.errors import CosimError
from cosim.core.pacing import Reading
from cosim.core.plants import OpenedPlant, PlantContext
from cosim.live.session import PlantSession

__all__ = ["LivePlant", "open_live"]


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
    #: its readings hold the measured disturbances (a live plant's are measured)
    reads_disturbances = True

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

    def start_values(self, values: Mapping[str, float]) -> None:
        """Nothing: a scenario sets nothing on a live plant."""

    def read(self, t: float = 0.0) -> Reading:
        """Read the outputs and disturbances; :meth:`get_outputs` returns them after."""
        reading = self.session.read()
        self.values = reading.values
        return reading

    def advance(self, t: float, dt: float) -> None:
        """Nothing: a live plant runs on its own clock."""

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


def open_live(plant: str, ctx: PlantContext) -> OpenedPlant:
    """The live plant at the endpoint ``plant`` (``opc.tcp://...``), bound to the run's
    problem, on the wall clock (:class:`cosim.live.clock.WallClock`): the opener of the
    ``opc.tcp`` scheme (:mod:`cosim.core.plants`), which :func:`cosim.api.run` runs.

    Raises
    ------
    CosimError
        A scenario column that would set the plant, bad live options, an unreadable tags
        file.
    """
    from cosim.live import tags as tags_mod
    from cosim.live.clock import LiveConfig, WallClock, refused_columns
    from cosim.live.runner import LiveOptions, check_endpoint

    if ctx.varmap is not None or ctx.interface != "cs":
        raise CosimError(f"--plant {plant}: a live plant takes no --map or --interface "
                         "(a tags file maps its names: --tags)")
    check_endpoint(plant, "--plant")
    live = ctx.live or LiveOptions()
    bound = ctx.problem
    if bound is None:   # a controller of its own signals (an FMU): the default problem's
        from cosim.adapters.problems import load_problem

        bound = load_problem(None)
    sc = ctx.scenario
    column = refused_columns(sc)
    if column is not None:
        raise CosimError(f"{sc.path}:1:1: column '{column}': a live plant is not set by the "
                         "scenario (its disturbances are measured, its parameters are the "
                         "plant's); perturb a virtual plant through cosim serve-plant's "
                         "writable variables")
    if not (live.speed > 0 and math.isfinite(live.speed)):
        raise CosimError(f"--speed {live.speed!r}: must be a positive number (the plant's "
                         "speed-up K)")
    if live.watchdog is not None and live.watchdog < 1:
        raise CosimError(f"--watchdog {live.watchdog!r}: must be a whole number of samples "
                         ">= 1")
    if ctx.step is not None:
        raise CosimError("--step: a live run steps at the controller's sample time")
    signals = [c.name for c in (*bound.inputs, *bound.outputs, *bound.disturbances)]
    tags = tags_mod.load(live.tags, signals) if live.tags is not None else tags_mod.Tags()
    period = bound.Ts / live.speed
    session = PlantSession(plant, reads=[c.name for c in (*bound.outputs, *bound.disturbances)],
                           writes=[c.name for c in bound.inputs], tags=tags, folder=bound.name,
                           security=live.security, max_age=period * (1 + 1e-3) + 0.002,
                           timeout=min(max(0.5 * period, 0.1), 5.0))
    component = LivePlant(bound, session)
    notice = ctx.on_notice or (lambda text: None)
    if not live.security.secure:
        notice("warning: no security (--security None): the plant's values travel unsigned "
               "and unencrypted")
    clock = WallClock(component, LiveConfig(
        period=period, watchdog=live.watchdog, notice=notice,
        describe={"endpoint": plant, "speed": live.speed,
                  "security": live.security.describe(),
                  "tags": str(live.tags) if live.tags else None}))
    return OpenedPlant(component, io=component, pacer=clock,
                       meta={"plant": plant, "fmi_version": "OPC UA", "interface": "opc.tcp",
                             "live": True})
