"""A virtual plant: a plant FMU served as an OPC UA server, stepped on the wall clock.

Before a controller meets a plant, process engineers rehearse it against a simulation served
over the plant's own interface (virtual commissioning). :class:`VirtualPlant` is that
simulation for any plant FMU bound to a control problem (``cosim serve-plant``). Its address
space, below Objects::

    <problem>/                     a folder named for the problem (its namespace:
                                   urn:gru-mpc-cosim:<problem>)
        <output>                   AnalogItem, read-only: the measurement, with its
                                   EngineeringUnits and EURange, republished every sample
                                   with the sample's source timestamp
        <input>                    AnalogItem, writable: the manipulated input, applied from
                                   the next sample on (clipped to its box)
        <disturbance>              AnalogItem, writable: a measured disturbance, applied to
                                   the plant and republished every sample as a measurement
        Parameters/<name>          the FMU's tunable parameters, writable (a perturbation)
        Simulation/Time            the plant's time [s]
        Simulation/Speed           the speed-up K: one sample every Ts/K seconds
        Simulation/Frozen          writable: the plant holds its state while true
        Simulation/StaleOutputs    writable: the outputs stop being republished (a rehearsal
                                   of a frozen transmitter: their timestamps age)
        Simulation/BadOutputs      writable: the outputs are published with status
                                   BadSensorFailure

Node ids are strings, ``ns=<idx>;s=<problem>.<name>`` (``ns=2;s=fourtank.h1``). Each sample
(every ``Ts / speed`` seconds of the wall clock) the plant advances one ``Ts`` with the
inputs as last written and its new outputs are published: an input written between two
samples acts from the next one, as in the co-simulation master (zero-order hold). Started
frozen (``frozen=True``), the plant holds its initial state until a client first writes an
input, so that a rehearsal starts where an in-process run starts.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cosim.core.component import Component
from cosim.live import quiet_libraries
from cosim.live.security import Security, secure_server

__all__ = ["APPLICATION_URI", "DEFAULT_ENDPOINT", "VirtualPlant"]

#: The application URI of ``cosim serve-plant`` (its certificate must carry it).
APPLICATION_URI = "urn:gru-mpc-cosim:plant"
#: Where ``cosim serve-plant`` listens by default.
DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"


class VirtualPlant:
    """Serve ``plant`` (bound to ``problem``) over OPC UA (see the module docstring).

    Parameters
    ----------
    plant : Component
        The plant (an FMU component bound to the problem's signal names), not yet set up.
    problem : ControlProblem
        Its inputs, outputs and measured disturbances (names, units, boxes) and ``Ts``.
    endpoint : str
        ``opc.tcp://host:port``.
    speed : float
        The speed-up K: one sample every ``Ts / K`` seconds.
    security : Security
    frozen : bool
        Hold the initial state until a client writes an input.
    record : path, optional
        Stream the plant's trajectory there (CSV: ``time``, inputs, disturbances, outputs;
        one row per sample, as ``results.csv``'s ``ctrl.*``/``dist.*``/``plant.*`` columns).
    notice : callable
        Takes the server's one-line messages.
    """

    def __init__(self, plant: Component, problem: Any, *, endpoint: str = DEFAULT_ENDPOINT,
                 speed: float = 1.0, security: Security | None = None, frozen: bool = False,
                 record: str | Path | None = None,
                 notice: Callable[[str], None] = print) -> None:
        self.plant, self.problem = plant, problem
        self.endpoint, self.speed = endpoint, float(speed)
        self.security = security or Security()
        self.frozen, self.thaw_on_write = frozen, frozen
        self.record_path = Path(record) if record is not None else None
        self.notice = notice
        self.period = problem.Ts / self.speed
        self.t = 0.0
        self.samples = 0
        self.overruns = 0
        self.clipped = 0
        self._written: set[str] = set()
        self._nodes: dict[str, Any] = {}
        self.tunables = frozenset(getattr(plant, "tunables", ()))
        self.parameters = sorted(self.tunables - {c.name for c in problem.disturbances})
        #: The record's columns (``--record``), as ``results.csv`` names them.
        self.columns = ["time", *(f"ctrl.{c.name}" for c in problem.inputs),
                        *(f"dist.{c.name}" for c in problem.disturbances),
                        *(f"plant.{c.name}" for c in problem.outputs)]
        self._param_values: dict[str, float] = {}

    # -- the address space ----------------------------------------------------------------
    async def _server(self) -> Any:
        from asyncua import Server

        users = _OneUser(self.security) if self.security.user is not None else None
        server = Server(user_manager=users)
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name(f"cosim serve-plant: {self.problem.name}")
        await server.set_application_uri(APPLICATION_URI)
        await secure_server(server, self.security, users is not None)
        self._aspace = server.iserver.aspace
        await self._address_space(server)
        server.subscribe_server_callback(_post_write(), self._on_write)
        return server

    async def _address_space(self, server: Any) -> None:
        from asyncua import ua

        name = self.problem.name
        idx = await server.register_namespace(f"urn:gru-mpc-cosim:{name}")
        self.idx = idx
        folder = await server.nodes.objects.add_folder(ua.NodeId(name, idx), ua.QualifiedName(
            name, idx))
        y0 = self.plant.get_outputs()
        for role, chans in (("output", self.problem.outputs), ("input", self.problem.inputs),
                            ("disturbance", self.problem.disturbances)):
            for c in chans:
                start = y0[c.name] if role == "output" else _start(self.plant, c.name)
                if not math.isfinite(start):
                    start = 0.5 * (c.min + c.max)
                self._nodes[c.name] = await _analog_item(server, folder, idx, f"{name}.{c.name}",
                                                         c, start, writable=role != "output")
        params = await folder.add_folder(ua.NodeId(f"{name}.Parameters", idx),
                                         ua.QualifiedName("Parameters", idx))
        for p in self.parameters:
            value = _start(self.plant, p)
            self._param_values[p] = value
            node = await params.add_variable(ua.NodeId(f"{name}.Parameters.{p}", idx),
                                             ua.QualifiedName(p, idx), value,
                                             varianttype=ua.VariantType.Double)
            await node.set_writable()
            self._nodes["Parameters." + p] = node
        sim = await folder.add_folder(ua.NodeId(f"{name}.Simulation", idx),
                                      ua.QualifiedName("Simulation", idx))
        for key, value, vt, writable in (
                ("Time", 0.0, ua.VariantType.Double, False),
                ("Speed", self.speed, ua.VariantType.Double, False),
                ("Frozen", self.frozen, ua.VariantType.Boolean, True),
                ("StaleOutputs", False, ua.VariantType.Boolean, True),
                ("BadOutputs", False, ua.VariantType.Boolean, True)):
            node = await sim.add_variable(ua.NodeId(f"{name}.Simulation.{key}", idx),
                                          ua.QualifiedName(key, idx), value, varianttype=vt)
            if writable:
                await node.set_writable()
            self._nodes["Simulation." + key] = node

    async def _on_write(self, event: Any, dispatcher: Any) -> None:
        """A client's write: remember which inputs it touched (a frozen start thaws)."""
        if not event.is_external:
            return
        for item in event.request_params.NodesToWrite:
            ident = item.NodeId.Identifier
            if isinstance(ident, str) and ident.startswith(self.problem.name + "."):
                self._written.add(ident[len(self.problem.name) + 1:])

    # -- serving ----------------------------------------------------------------------------
    async def serve(self, stop: asyncio.Event, duration: float | None = None) -> None:
        """Serve until ``stop`` is set or ``duration`` seconds [wall clock] have passed."""
        quiet_libraries()
        self.plant.setup(0.0)
        self.t = 0.0
        server = await self._server()
        stream = None
        if self.record_path is not None:
            from cosim.core.results import ResultsStream

            stream = ResultsStream(self.record_path)
        try:
            async with server:
                if not self.security.secure:
                    self.notice("warning: no security (--security None): anyone who reaches "
                                "the endpoint can read and write this plant")
                self.notice(f"serving '{self.problem.name}' at {self.endpoint} (security "
                            f"{self.security.describe()}), one sample every "
                            f"{self.period:g} s (speed {self.speed:g})"
                            + ("; frozen until a client writes an input" if self.frozen
                               else ""))
                await self._ticks(stop, duration, stream)
        finally:
            with contextlib.suppress(Exception):
                self.plant.terminate()
            if stream is not None:
                stream.finish(self.columns, [])   # every row was streamed

    async def _ticks(self, stop: asyncio.Event, duration: float | None, stream: Any) -> None:
        loop = asyncio.get_running_loop()
        end = loop.time() + duration if duration is not None else math.inf
        y = self.plant.get_outputs()
        await self._publish(y, fresh=True)
        tick = loop.time()
        while not stop.is_set():
            tick += self.period
            wait = min(tick, end) - loop.time()
            if wait > 0:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), wait)
            elif wait < -self.period:       # fell more than a sample behind: resynchronise
                self.overruns += 1
                tick = loop.time()
            if stop.is_set() or loop.time() >= end:
                break
            y = await self._sample(y, stream)
            await self._publish(y, fresh=not self._flag("StaleOutputs"))

    async def _sample(self, y: dict[str, float], stream: Any) -> dict[str, float]:
        """One sample: thaw on a first write, step the plant with the inputs written."""
        if self.thaw_on_write and self._written & {c.name for c in self.problem.inputs}:
            self.thaw_on_write = False
            await self._set_flag("Frozen", False)
        self.frozen = self._flag("Frozen")
        if self.frozen:
            return y
        p, plant = self.problem, self.plant
        u = {c.name: self._input(c) for c in p.inputs}
        d = {c.name: self._input(c) for c in p.disturbances}
        if stream is not None:
            stream.append([self.t, *u.values(), *d.values(), *(y[c.name] for c in p.outputs)],
                          self.columns)
        plant.set_inputs({**u, **{k: v for k, v in d.items() if k not in self.tunables}})
        for k, v in d.items():
            if k in self.tunables:
                plant.set_parameter(k, v)
        for name in self.parameters:
            v = self._read("Parameters." + name)
            if math.isfinite(v) and v != self._param_values[name]:
                plant.set_parameter(name, v)
                self._param_values[name] = v
        plant.step(self.t, p.Ts)
        self.t += p.Ts
        self.samples += 1
        return plant.get_outputs()

    def _input(self, channel: Any) -> float:
        value = self._read(channel.name)
        clipped = min(max(value, channel.min), channel.max) if math.isfinite(value) \
            else 0.5 * (channel.min + channel.max)
        if clipped != value:
            self.clipped += 1
            if self.clipped == 1:
                self.notice(f"'{channel.name}' = {value!r} {channel.unit} is outside its box "
                            f"[{channel.min:g}, {channel.max:g}]: clipped (counted from now)")
        return clipped

    def _read(self, key: str) -> float:
        """A variable's value now, read from the address space at once (no await: no other
        request can come between this read and what the sample does with it)."""
        from asyncua import ua

        dv = self._aspace.read_attribute_value(self._nodes[key].nodeid, ua.AttributeIds.Value)
        value = dv.Value.Value if dv.Value is not None else None
        try:
            return float(value)
        except (TypeError, ValueError):
            return math.nan

    def _flag(self, key: str) -> bool:
        return bool(self._read("Simulation." + key) == 1.0)

    async def _set_flag(self, key: str, value: bool) -> None:
        from asyncua import ua

        await self._nodes["Simulation." + key].write_value(value, ua.VariantType.Boolean)

    async def _publish(self, y: dict[str, float], fresh: bool) -> None:
        """The outputs (unless stale) and disturbances, stamped now; the plant's time."""
        from asyncua import ua

        now = datetime.now(UTC)
        bad = self._flag("BadOutputs")
        status = ua.StatusCode(ua.StatusCodes.BadSensorFailure if bad else ua.StatusCodes.Good)
        if fresh:
            for c in self.problem.outputs:
                await self._write(c.name, y[c.name], now, status)
        for c in self.problem.disturbances:
            await self._write(c.name, self._read(c.name), now, ua.StatusCode())
        await self._write("Simulation.Time", self.t, now, ua.StatusCode())

    async def _write(self, key: str, value: float, now: datetime, status: Any) -> None:
        from asyncua import ua

        node = self._nodes[key]
        await node.write_value(ua.DataValue(ua.Variant(float(value), ua.VariantType.Double),
                                            StatusCode=status, SourceTimestamp=now,
                                            ServerTimestamp=now))


def _post_write() -> Any:
    from asyncua.common.callback import CallbackType

    return CallbackType.PostWrite


async def _analog_item(server: Any, folder: Any, idx: int, ident: str, channel: Any,
                       value: float, writable: bool) -> Any:
    """An AnalogItem variable (Double) with its EURange and EngineeringUnits."""
    from asyncua import ua
    from asyncua.common.instantiate_util import instantiate

    node_type = server.get_node(ua.NodeId(ua.ObjectIds.AnalogItemType))
    nodes = await instantiate(folder, node_type, nodeid=ua.NodeId(ident, idx),
                              bname=ua.QualifiedName(channel.name, idx),
                              dname=ua.LocalizedText(channel.name), idx=idx,
                              instantiate_optional=False)
    node = nodes[0]
    await node.write_attribute(ua.AttributeIds.DataType,
                               ua.DataValue(ua.Variant(ua.NodeId(ua.ObjectIds.Double),
                                                       ua.VariantType.NodeId)))
    await node.write_value(ua.Variant(float(value), ua.VariantType.Double))
    if channel.description:
        await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText(channel.description), ua.VariantType.LocalizedText)))
    eu_range = await node.get_child(["0:EURange"])
    await eu_range.write_value(ua.Range(Low=channel.min, High=channel.max))
    await node.add_property(ua.NodeId(f"{ident}.EngineeringUnits", idx),
                            ua.QualifiedName("EngineeringUnits", 0), ua.EUInformation(
        NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact", UnitId=-1,
        DisplayName=ua.LocalizedText(channel.unit), Description=ua.LocalizedText(channel.unit)))
    if writable:
        await node.set_writable()
    return node


def _start(plant: Any, name: str) -> float:
    """A tunable parameter's start value (NaN when the FMU gives none)."""
    with contextlib.suppress(Exception):
        return float(plant.variable_of(name).start)
    return math.nan


class _OneUser:
    """A user manager that accepts one user and password."""

    def __init__(self, security: Security) -> None:
        self.name, self.password = security.user, security.password

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        if username == self.name and password == self.password:
            return User(role=UserRole.User, name=username)
        return None
