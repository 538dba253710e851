"""A live plant as the master sees it: the problem's signals, read and written over OPC UA.

:class:`LivePlant` is a :class:`~cosim.core.component.Component` (its signals, for the
wiring) and the run's plant I/O (:class:`cosim.core.pacing.PlantIO`): its readings are the
measurements read over OPC UA, fresh or not (:meth:`LivePlant.read`; the problem's
plausibility checks, :mod:`cosim.live.screen`, once a sample: :meth:`LivePlant.screen`), its
inputs are written to the plant (:meth:`LivePlant.write`), never outside their box, with the
heartbeat's counter when one is asked for, and it does not advance (the plant runs on its own
clock). Its measured disturbances are read like its outputs. :meth:`LivePlant.write_safe`
writes the safe inputs and reads them back; :meth:`LivePlant.terminate` writes them (once the
run has written to the plant) and closes the session.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from cosim.core.component import Component, Signal
from cosim.core.errors import CosimError
from cosim.core.pacing import Reading
from cosim.core.plants import OpenedPlant, PlantContext
from cosim.live.screen import Screen
from cosim.live.session import HEARTBEAT, INTEGER_RANGES, LINK_DOWN, PlantSession

__all__ = ["LivePlant", "open_live"]


class LivePlant(Component):
    """The problem's plant behind an OPC UA session (see the module docstring).

    Parameters
    ----------
    problem : ControlProblem
        Inputs (written, with their boxes and ``safe`` values), outputs and measured
        disturbances (read, with their ``valid``, ``rate`` and ``frozen`` checks).
    session : PlantSession
        Not yet connected (:meth:`setup` connects).

    Attributes
    ----------
    written : dict
        The last values written to each input.
    clipped : int
        Values the controller asked for outside their box (written at the box's edge).
    write_failures : int
        Writes (of inputs or of the heartbeat) that did not all reach the plant.
    refused : dict
        Per input (and ``heartbeat``), the writes of it that did not reach the plant.
    heartbeats : int
        Heartbeats written.
    reached : bool
        Whether the last :meth:`write` brought at least one input to the plant.
    end : str
        What :meth:`terminate` did to the inputs.
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
        self.refused: dict[str, int] = {}
        self.heartbeats = 0
        self.reached = False
        self.end = ""
        self.screen = Screen((*problem.outputs, *problem.disturbances), problem.Ts,
                             problem.output_names)
        self._beat: int | None = None

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

    # -- the heartbeat --------------------------------------------------------------------
    def begin_sample(self, k: int) -> None:
        """Sample ``k`` begins: its heartbeat is due (with the inputs, else alone)."""
        if self.session.heartbeat is not None:
            self._beat = k

    def end_sample(self) -> None:
        """The heartbeat of the sample, when no input write carried it."""
        if self._beat is not None:
            self._write({})

    def _counter(self, k: int) -> float:
        """The heartbeat's value at sample ``k``: a counter that wraps within the node's
        type (a Boolean toggles)."""
        type_name = self.session.nodes[HEARTBEAT].type_name
        if type_name == "Boolean":
            return float(k % 2)
        top = INTEGER_RANGES.get(type_name, (0, 2 ** 24 - 1))[1]
        return float(k % (min(top, 2 ** 31 - 1) + 1))

    # -- writing ------------------------------------------------------------------------------
    def write(self, values: Mapping[str, float]) -> bool:
        """Write the inputs among ``values``, each clipped to its box (a NaN is not
        written); whether they all reached the plant."""
        out = {}
        for name, value in values.items():
            box = self.boxes.get(name)
            if box is None or not math.isfinite(value):
                continue
            v = min(max(float(value), box[0]), box[1])
            if v != value:
                self.clipped += 1
            out[name] = v
        failed = self._write(out)
        self.reached = any(name not in failed for name in out)
        return bool(out) and not any(name in failed for name in out)

    def _write(self, out: dict[str, float]) -> dict[str, str]:
        """Write ``out`` (and the heartbeat when due) in one call; what did not reach the
        plant, counted."""
        beat = self._beat
        if beat is not None:
            out = {**out, HEARTBEAT: self._counter(beat)}
            self._beat = None
        if not out:
            return {}
        failed = self.session.write(out)
        self.written.update((k, v) for k, v in out.items()
                            if k not in failed and k != HEARTBEAT)
        if beat is not None and HEARTBEAT not in failed:
            self.heartbeats += 1
        if failed:
            self.write_failures += 1
            for name in failed:
                key = "heartbeat" if name == HEARTBEAT else name
                self.refused[key] = self.refused.get(key, 0) + 1
        return failed

    def write_safe(self) -> tuple[dict[str, float], str]:
        """Write the inputs' safe values (inputs without one hold their last) and read them
        back: the values that reached the plant, and ``""`` when the plant holds them all
        now, else why not (``"link down"``, a refusal, a value read back)."""
        if not self.safe:
            return {}, "no safe inputs declared"
        failed = self._write(dict(self.safe))
        written = {k: v for k, v in self.safe.items() if k not in failed}
        if failed:
            whys = sorted(set(failed.values()))
            return written, (LINK_DOWN if whys == [LINK_DOWN] else
                             "; ".join(f"{k}: {w}" for k, w in failed.items()))
        return written, self.session.read_back(self.safe)

    def terminate(self) -> None:
        """Write the safe inputs, when this run has written to the plant (one that never
        took control leaves it as it was), and close the session; safe to call twice.
        :attr:`end` says what it did."""
        if not self.end:
            if not self.written:
                self.end = "nothing written: the run never wrote to the plant"
            elif not self.safe:
                self.end = "no safe inputs declared: the inputs hold their last values"
            else:
                why = self.write_safe()[1] if self.session.connected else LINK_DOWN
                self.end = "safe inputs written" if not why else \
                    f"safe inputs not written: {why}"
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
                         "(a tags file maps its names and units: --tags)")
    check_endpoint(plant, "--plant")
    live = ctx.live or LiveOptions()
    live.check()
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
    if ctx.step is not None:
        raise CosimError("--step: a live run steps at the controller's sample time")
    units = bound.units()
    tags = (tags_mod.load(live.tags, list(units), units) if live.tags is not None
            else tags_mod.Tags())
    heartbeat = (tags_mod.tag_of("heartbeat", live.heartbeat, "--heartbeat")
                 if live.heartbeat is not None else None)
    period = bound.Ts / live.speed
    session = PlantSession(plant, reads=[c.name for c in (*bound.outputs, *bound.disturbances)],
                           writes=list(bound.input_names), tags=tags, folder=bound.name,
                           security=live.security, max_age=period * (1 + 1e-3) + 0.002,
                           timeout=min(max(0.5 * period, 0.1), 5.0), units=units,
                           boxes=dict(zip(bound.input_names, bound.input_bounds, strict=True)),
                           heartbeat=heartbeat)
    component = LivePlant(bound, session)
    notice = ctx.on_notice or (lambda text: None)
    if not live.security.secure:
        notice("warning: no security (--security None): the plant's values travel unsigned "
               "and unencrypted")
    clock = WallClock(component, LiveConfig(
        period=period, watchdog=live.watchdog, notice=notice,
        min_controlled=live.min_controlled,
        describe={"endpoint": plant, "speed": live.speed,
                  "security": live.security.describe(),
                  "tags": str(live.tags) if live.tags else None,
                  "heartbeat": live.heartbeat}))
    return OpenedPlant(component, io=component, pacer=clock,
                       meta={"plant": plant, "fmi_version": "OPC UA", "interface": "opc.tcp",
                             "live": True})
