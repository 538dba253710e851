"""The OPC UA client of a live run: connect, find the tags, read measurements, write inputs.

:class:`PlantSession` runs asyncua's client on an event loop of its own, in the run's thread:
during each request (bounded in time) and while the run waits for its next sample
(:meth:`PlantSession.idle`, where keep-alives and reconnections go on), never in another
thread, so that a request costs no hand-over between threads; signals reach the run between
requests (:mod:`cosim.core.interrupts`). A sample costs two service calls, their requests
built once at connection: one Read of every measurement (values, status, both timestamps)
and one Write of every input (and the heartbeat), each value in its tag's unit and data type
(:mod:`cosim.live.tags`, :mod:`cosim.live.nodes`). What a live process does to a
connection is answered here:

* the first connection fails (unreachable, refused certificate or user, a tag the server
  lacks or in another unit, an input it cannot carry): one line naming the endpoint and why
  (:class:`~cosim.core.errors.CosimError`, exit 2), nothing written;
* a read that fails, or finds a value whose status is not Good, whose source timestamp is
  older than ``max_age`` or further than ``max_age`` in the future, that is not finite or
  lies outside its node's EURange: that signal is *not fresh*, and :class:`Reading` says
  why;
* a write that a node refuses: the others are written, the refused ones named
  (:meth:`PlantSession.write`);
* the connection drops: reads say "disconnected" while a background task reconnects with
  back-off (0.1 s doubling to 2 s) and finds the tags again; :attr:`PlantSession.reconnects`
  counts the times it came back.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from datetime import UTC
from typing import Any

from cosim.core import interrupts
from cosim.core.errors import CosimError
from cosim.core.pacing import Reading
from cosim.live import nodes as nodes_mod
from cosim.live import quiet_libraries
from cosim.live.nodes import INTEGER_RANGES, Node
from cosim.live.security import Security, validator
from cosim.live.tags import Tag, Tags

__all__ = ["APPLICATION_URI", "HEARTBEAT", "LINK_DOWN", "PlantSession", "Reading"]

#: The application URI of ``cosim run``'s client (its certificate must carry it).
APPLICATION_URI = "urn:gru-mpc-cosim:client"
#: Reconnection back-off: first wait and longest wait [s].
BACKOFF = (0.1, 2.0)
#: The heartbeat's name among the values written (not a signal's: it has a dot).
HEARTBEAT = "live.heartbeat"
#: Why a write did not reach the plant when the connection is down.
LINK_DOWN = "link down"
#: The longest stretch [s] the event loop runs between two looks for a signal while idle.
IDLE_SLICE = 0.05


class PlantSession:
    """A connection to a live plant's OPC UA server (see the module docstring).

    Parameters
    ----------
    endpoint : str
        ``opc.tcp://host:port[/path]``.
    reads, writes : sequence of str
        The signals read each sample (outputs, then measured disturbances) and written
        (the inputs).
    tags : Tags
        Where each signal lives, and in what unit (:mod:`cosim.live.tags`).
    folder : str
        The folder below Objects where untagged signals are looked up (the problem's name),
        unless the tags file sets a root.
    security : Security
    max_age : float
        A value whose source timestamp is older than this [s], or further in the future, is
        not fresh.
    timeout : float
        Longest wait for one request [s].
    units : mapping, optional
        The problem's unit of each signal (what a tag without a unit must be in).
    boxes : mapping, optional
        Each input's box (what an integer node must carry).
    heartbeat : Tag, optional
        A node written with a counter every sample (:data:`HEARTBEAT` among the values).

    Attributes
    ----------
    nodes : dict of str to Node
        Each signal's node as the server described it at the last connection.
    """

    def __init__(self, endpoint: str, *, reads: Sequence[str], writes: Sequence[str],
                 tags: Tags, folder: str, security: Security, max_age: float,
                 timeout: float, units: Mapping[str, str] | None = None,
                 boxes: Mapping[str, tuple[float, float]] | None = None,
                 heartbeat: Tag | None = None) -> None:
        if not endpoint.startswith("opc.tcp://"):
            raise CosimError(f"--plant {endpoint}: an OPC UA endpoint starts with opc.tcp://")
        self.endpoint = endpoint
        self.reads, self.writes = list(reads), list(writes)
        self.tags, self.folder, self.security = tags, folder, security
        self.max_age, self.timeout = float(max_age), float(timeout)
        self.units, self.boxes = dict(units or {}), dict(boxes or {})
        self.heartbeat = heartbeat
        self.reconnects = 0
        self.connected = False
        self.nodes: dict[str, Node] = {}
        self._client: Any = None
        self._requests: dict[tuple[str, ...], tuple[Any, list[Any]]] = {}
        self._read: Any = None
        self._reconnecting: Any = None
        self._closing = False
        self._loop = asyncio.new_event_loop()
        self._loop.set_exception_handler(lambda loop, context: None)
        quiet_libraries()

    # -- running the session's event loop -------------------------------------------------
    def _call(self, coro: Any, timeout: float) -> Any:
        """Run ``coro`` on the session's event loop, in the calling thread (no hop into
        another thread: a sample's two calls cost what the messages cost), for at most
        ``timeout`` seconds; a signal meanwhile is recorded, not raised inside asyncua, and
        raised by the run's next check (:mod:`cosim.core.interrupts`)."""
        guard = interrupts.current()
        with guard.deferred() if guard is not None else contextlib.nullcontext():
            return self._loop.run_until_complete(asyncio.wait_for(coro, timeout))

    def idle(self, until: float) -> None:
        """Let the connection live until ``time.perf_counter()`` reaches ``until`` (its
        keep-alive, a reconnection in progress); a signal ends the wait and is raised here
        (:class:`~cosim.core.interrupts.Interrupted`)."""
        guard = interrupts.current()
        with guard.deferred() if guard is not None else contextlib.nullcontext():
            while (left := until - time.perf_counter()) > 0 and \
                    (guard is None or guard.signum is None):
                self._loop.run_until_complete(asyncio.sleep(min(left, IDLE_SLICE)))
        if guard is not None:
            guard.check()

    # -- connecting ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Connect, find every tag and check its node (:func:`cosim.live.nodes.check`): the
        run's first connection.

        Raises
        ------
        CosimError
            Unreachable endpoint, refused certificate or user, a tag the server lacks, in
            another unit or of a type the signal cannot be, an input it does not let this
            user write.
        """
        try:
            self._call(self._open(), 4 * self.timeout + 10.0)
        except CosimError:
            raise
        except Exception as exc:
            raise CosimError(f"--plant {self.endpoint}: cannot connect: "
                             f"{_why(exc, self.security)}") from None

    async def _open(self) -> None:
        from asyncua import Client

        client = Client(self.endpoint, timeout=max(self.timeout, 1.0))
        client.application_uri = APPLICATION_URI
        client.name = "cosim run"
        sec = self.security
        if sec.secure:
            from asyncua import ua
            from asyncua.crypto import security_policies

            client.certificate_validator = await validator(sec, "server")

            await client.set_security(
                getattr(security_policies, f"SecurityPolicy{sec.policy}"),
                str(sec.certificate), str(sec.private_key),
                mode=getattr(ua.MessageSecurityMode, sec.mode))
        if sec.user is not None:
            client.set_user(sec.user)
            client.set_password(sec.password or "")
        await client.connect()
        try:
            await self._resolve(client)
        except BaseException:
            with contextlib.suppress(Exception):
                await client.disconnect()
            raise
        self._client = client
        self.connected = True

    async def _resolve(self, client: Any) -> None:
        """Find and check every signal's node (and the heartbeat's); build the requests."""
        signals = list(dict.fromkeys([*self.reads, *self.writes]))
        tags = {s: self.tags.tag(s) for s in signals}
        if self.heartbeat is not None:
            tags[HEARTBEAT] = self.heartbeat
        base = None
        if any(t.node_id is None and not t.absolute for t in tags.values()):
            root = self.tags.root
            base = (await nodes_mod.walk(client.nodes.objects, root, "the tags file's root")
                    if root is not None else await nodes_mod.walk(
                        client.nodes.objects, ((None, self.folder),),
                        f"the folder '{self.folder}' (the problem's name; give a tags file "
                        "for a plant laid out otherwise)"))
        found = {}
        for signal, tag in tags.items():
            label = "--heartbeat" if signal == HEARTBEAT else f"signal '{signal}'"
            node = await nodes_mod.find(client, base, label, tag, self.endpoint)
            info = await nodes_mod.describe(node, signal, tag, signal not in self.reads)
            if signal == HEARTBEAT:
                info = _heartbeat(info, self.endpoint)
            else:
                nodes_mod.check(info, self.units.get(signal, ""), self.boxes.get(signal),
                                self.endpoint)
            found[signal] = info
        self.nodes, self._requests = found, {}
        self._read = _read_request([found[s] for s in self.reads])

    # -- reading and writing -----------------------------------------------------------------
    def read(self) -> Reading:
        """The measured signals now, in the problem's units; never raises (a failure makes
        them not fresh)."""
        data = self._service(self._read) if self.connected else None
        if isinstance(data, str) or data is None:
            return self._nothing(data or "disconnected")
        return self._reading(data)

    def _service(self, request: Any) -> Any:
        """One Read or Write service call: its results, or why none came (a string)."""
        from asyncua import ua

        client = self._client
        call = (client.uaclient.read if isinstance(request, ua.ReadParameters)
                else client.uaclient.write)
        try:
            return self._call(call(request), self.timeout)
        except TimeoutError:
            return f"no answer within {self.timeout:g} s"
        except Exception:
            self._lost()
            return "disconnected"

    def _nothing(self, why: str) -> Reading:
        """A read that brought no value: every signal NaN, not fresh for ``why``."""
        if not self.connected:
            self._start_reconnect()
        return Reading(dict.fromkeys(self.reads, math.nan), dict.fromkeys(self.reads, why))

    def _reading(self, data: list[Any]) -> Reading:
        now, limit = time.time(), self.max_age
        out, stale, newest = {}, {}, None
        for signal, dv in zip(self.reads, data, strict=True):
            node = self.nodes[signal]
            value = dv.Value.Value if dv.Value is not None else None
            try:
                raw = float(value)
            except (TypeError, ValueError):
                raw = math.nan
            out[signal] = node.tag.from_plant(raw)
            status = dv.StatusCode
            source = dv.SourceTimestamp or dv.ServerTimestamp
            ts = source.replace(tzinfo=source.tzinfo or UTC).timestamp() if source else None
            rng = node.eurange
            if status is not None and not status.is_good():
                stale[signal] = f"status {status.name}"
            elif ts is None:
                stale[signal] = "no timestamp"
            elif now - ts > limit:
                stale[signal] = f"older than a sample ({now - ts:.3g} s)"
            elif ts - now > limit:
                stale[signal] = f"stamped in the future ({ts - now:.3g} s ahead)"
            elif not math.isfinite(raw):
                stale[signal] = f"value {value!r}"
            elif rng is not None and not rng[0] <= raw <= rng[1]:
                stale[signal] = (f"outside its EURange ({raw:g} not in [{rng[0]:g}, "
                                 f"{rng[1]:g}] {node.unit or ''})".replace(" )", ")"))
            if ts is not None and (newest is None or ts > newest):
                newest = ts
        return Reading(out, stale, newest)

    def write(self, values: Mapping[str, float]) -> dict[str, str]:
        """Write ``values`` (the problem's units, already in the input box; the heartbeat's
        counter under :data:`HEARTBEAT`) in one Write call, each in its tag's unit and type;
        the names that did not reach the plant, with why (empty: all did)."""
        if not values:
            return {}
        if not self.connected:
            return dict.fromkeys(values, LINK_DOWN)
        names = tuple(values)
        request, variants = self._write_request(names)
        for name, variant in zip(names, variants, strict=True):
            variant.Value = self._raw(name, values[name])
        results = self._service(request)
        if isinstance(results, str):
            return dict.fromkeys(names, LINK_DOWN if results == "disconnected" else results)
        return {n: f"refused ({st.name})" for n, st in zip(names, results, strict=True)
                if not st.is_good()}

    def read_back(self, values: Mapping[str, float]) -> str:
        """Whether the plant's input nodes hold ``values`` now (as written: in their types):
        ``""`` when they do, else why not."""
        names = list(values)
        data = self._service(_read_request([self.nodes[n] for n in names])) \
            if self.connected else LINK_DOWN
        if isinstance(data, str):
            return LINK_DOWN if data == "disconnected" else data
        for name, dv in zip(names, data, strict=True):
            want = float(self._raw(name, values[name]))
            got = dv.Value.Value if dv.Value is not None else None
            if not (isinstance(got, int | float) and math.isclose(float(got), want,
                                                                  rel_tol=1e-6)):
                return f"{name} reads back {got!r}, not {want:g}"
        return ""

    def _write_request(self, names: tuple[str, ...]) -> tuple[Any, list[Any]]:
        """The Write request of ``names`` (built once per set of names) and its variants."""
        cached = self._requests.get(names)
        if cached is None:
            from asyncua import ua

            items = [ua.WriteValue(NodeId=self.nodes[n].node.nodeid,
                                   AttributeId=ua.AttributeIds.Value,
                                   Value=ua.DataValue(ua.Variant(0, self.nodes[n].vtype)))
                     for n in names]
            cached = (ua.WriteParameters(NodesToWrite=items), [w.Value.Value for w in items])
            self._requests[names] = cached
        return cached

    def _raw(self, name: str, value: float) -> float | int | bool:
        """``value`` as its node takes it: in the tag's unit, rounded and kept within range
        for an integer type."""
        node = self.nodes[name]
        if node.type_name == "Boolean":
            return bool(value)
        raw = node.tag.to_plant(value)
        limits = INTEGER_RANGES.get(node.type_name)
        if limits is None:
            return float(raw)
        return min(max(round(raw), limits[0]), limits[1])

    # -- losing and finding the connection ---------------------------------------------------
    def _lost(self) -> None:
        self.connected = False
        client, self._client = self._client, None
        if client is not None:
            self._loop.create_task(_quietly(client.disconnect()))
        self._start_reconnect()

    def _start_reconnect(self) -> None:
        """A reconnection in the background: it goes on whenever the loop runs (the waits
        between samples, :meth:`idle`)."""
        task = self._reconnecting
        if (task is None or task.done()) and not self._closing:
            self._reconnecting = self._loop.create_task(self._reconnect())

    async def _reconnect(self) -> None:
        delay = BACKOFF[0]
        while not self._closing:
            try:
                await asyncio.wait_for(self._open(), 4 * self.timeout + 5.0)
            except Exception:
                await asyncio.sleep(delay)
                delay = min(2 * delay, BACKOFF[1])
                continue
            self.reconnects += 1
            return

    def close(self) -> None:
        """Disconnect and close the session's event loop; safe to call more than once."""
        if self._closing:
            return
        self._closing = True
        client, self._client = self._client, None
        self.connected = False
        with contextlib.suppress(Exception):
            if client is not None:
                self._call(_quietly(client.disconnect()), 2.0)
            pending = asyncio.all_tasks(self._loop)
            for task in pending:
                task.cancel()
            self._loop.run_until_complete(asyncio.wait_for(
                asyncio.gather(*pending, return_exceptions=True), 2.0))
        self._loop.close()


async def _quietly(coro: Any) -> None:
    with contextlib.suppress(Exception):
        await coro


def _read_request(nodes: Sequence[Node]) -> Any:
    """One Read request of the values of ``nodes``, with both timestamps."""
    from asyncua import ua

    return ua.ReadParameters(
        TimestampsToReturn=ua.TimestampsToReturn.Both,
        NodesToRead=[ua.ReadValueId(NodeId=n.node.nodeid, AttributeId=ua.AttributeIds.Value)
                     for n in nodes])


def _heartbeat(node: Node, endpoint: str) -> Node:
    """The heartbeat's node, checked: writable, a number or a Boolean.

    Raises
    ------
    CosimError
        It is neither, or this user may not write it.
    """
    from asyncua import ua

    what = f"--heartbeat {node.tag.describe()}: at {endpoint}"
    if not node.writable:
        raise CosimError(f"{what}: the node is not writable by this user")
    if node.type_name == "Boolean":
        return dataclasses.replace(node, vtype=ua.VariantType.Boolean)
    if node.vtype is None:
        raise CosimError(f"{what}: its data type {node.type_name} is neither a number nor a "
                         "Boolean")
    return node


def _why(exc: BaseException, security: Security) -> str:
    """A connection failure in words."""
    name = type(exc).__name__
    code = getattr(exc, "code", None)
    text = " ".join(str(exc).split())
    if isinstance(exc, ConnectionRefusedError) or "Connect call failed" in text:
        return "connection refused (is the server running, is the port right?)"
    if isinstance(exc, TimeoutError | asyncio.TimeoutError):
        return "no answer (timed out)"
    if "BadUserAccessDenied" in name + text or "BadIdentityToken" in name + text:
        return (f"the server refused user {security.user!r} (wrong user or password)"
                if security.user else "the server requires a user (--user)")
    if "Certificate" in name + text or (code is not None and "Certificate" in str(code)):
        return ("the server's certificate is not trusted (not in the --trust list, expired or "
                f"for another application): {name}")
    if "BadSecurity" in name + text or "find_endpoint" in text or "No matching endpoints" in text:
        return (f"the server offers no endpoint with security {security.describe()} "
                f"({name})")
    return f"{name}: {text}" if text else name

