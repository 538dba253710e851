"""The OPC UA client of a live run: connect, find the tags, read measurements, write inputs.

:class:`PlantSession` keeps asyncua's client in an event loop of its own thread, so that the
run's loop stays in the main thread, on its clock and reachable by signals; every request is
bounded in time. What a live process does to a connection is answered here:

* the first connection fails (unreachable, refused certificate or user): one line naming the
  endpoint and why (:class:`~cosim.core.errors.CosimError`, exit 2), nothing written;
* a read that fails, or finds a value whose status is not Good or whose source timestamp is
  older than ``max_age``: that signal is *not fresh*, and :class:`Reading` says why;
* the connection drops: reads say "disconnected" while a background task reconnects with
  back-off (0.1 s doubling to 2 s) and finds the tags again; :attr:`PlantSession.reconnects`
  counts the times it came back.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
from collections.abc import Mapping, Sequence
from datetime import UTC
from typing import Any

from cosim.core.errors import CosimError
from cosim.core.pacing import Reading
from cosim.live import quiet_libraries
from cosim.live.security import Security, validator
from cosim.live.tags import Tag, Tags

__all__ = ["APPLICATION_URI", "PlantSession", "Reading"]

#: The application URI of ``cosim run``'s client (its certificate must carry it).
APPLICATION_URI = "urn:gru-mpc-cosim:client"
#: Reconnection back-off: first wait and longest wait [s].
BACKOFF = (0.1, 2.0)


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
        Where each signal lives (:mod:`cosim.live.tags`).
    folder : str
        The folder below Objects where untagged signals are looked up (the problem's name),
        unless the tags file sets a root.
    security : Security
    max_age : float
        A value whose source timestamp is older than this [s] is not fresh.
    timeout : float
        Longest wait for one request [s].
    """

    def __init__(self, endpoint: str, *, reads: Sequence[str], writes: Sequence[str],
                 tags: Tags, folder: str, security: Security, max_age: float,
                 timeout: float) -> None:
        if not endpoint.startswith("opc.tcp://"):
            raise CosimError(f"--plant {endpoint}: an OPC UA endpoint starts with opc.tcp://")
        self.endpoint = endpoint
        self.reads, self.writes = list(reads), list(writes)
        self.tags, self.folder, self.security = tags, folder, security
        self.max_age, self.timeout = float(max_age), float(timeout)
        self.reconnects = 0
        self.connected = False
        self._client: Any = None
        self._nodes: dict[str, Any] = {}
        self._types: dict[str, Any] = {}
        self._reconnecting: Any = None
        self._closing = False
        self._loop = asyncio.new_event_loop()
        self._loop.set_exception_handler(lambda loop, context: None)
        self._thread = threading.Thread(target=self._loop.run_forever, name="opcua",
                                        daemon=True)
        self._thread.start()
        quiet_libraries()

    # -- calls into the session's thread --------------------------------------------------
    def _call(self, coro: Any, timeout: float) -> Any:
        future = asyncio.run_coroutine_threadsafe(coro, self._loop)
        try:
            return future.result(timeout)
        except BaseException:
            future.cancel()
            raise

    # -- connecting ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Connect and find every tag (the run's first connection).

        Raises
        ------
        CosimError
            Unreachable endpoint, refused certificate or user, a tag the server lacks or an
            input it does not let this user write.
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
        """Find every signal's node, its data type and (inputs) that it is writable."""
        from asyncua import ua

        objects = client.nodes.objects
        root = self.tags.root
        base = (await _walk(objects, root, "the tags file's root") if root is not None
                else await _walk(objects, ((None, self.folder),),
                                 f"the folder '{self.folder}' (the problem's name; give a "
                                 "tags file for a plant laid out otherwise)"))
        nodes, types = {}, {}
        for signal in dict.fromkeys([*self.reads, *self.writes]):
            tag = self.tags.tag(signal)
            node = await self._node(client, objects, base, signal, tag)
            dtype = await node.read_data_type()
            types[signal] = _variant_type(dtype)
            nodes[signal] = node
            if signal in self.writes:
                level = await node.read_attribute(ua.AttributeIds.UserAccessLevel)
                if not int(level.Value.Value) & ua.AccessLevel.CurrentWrite.mask:
                    raise CosimError(f"--plant {self.endpoint}: input '{signal}' "
                                     f"({tag.describe()}) is not writable by this user")
        self._nodes, self._types = nodes, types

    async def _node(self, client: Any, objects: Any, base: Any, signal: str, tag: Tag) -> Any:
        from asyncua import ua

        what = f"signal '{signal}' ({tag.describe()}{', ' + tag.where if tag.where else ''})"
        if tag.node_id is not None:
            node = client.get_node(tag.node_id)
            try:
                await node.read_browse_name()
            except ua.UaStatusCodeError:
                raise CosimError(f"--plant {self.endpoint}: {what}: no such node") from None
            return node
        return await _walk(objects if tag.absolute else base, tag.path, what)

    # -- reading and writing -----------------------------------------------------------------
    def read(self) -> Reading:
        """The measured signals now; never raises (a failure makes them not fresh)."""
        if not self.connected:
            self._start_reconnect()
            return self._nothing("disconnected")
        try:
            values = self._call(self._client.read_attributes(
                [self._nodes[s] for s in self.reads]), self.timeout)
        except TimeoutError:
            return self._nothing(f"no answer within {self.timeout:g} s")
        except Exception:
            self._lost()
            return self._nothing("disconnected")
        return self._reading(values)

    def _nothing(self, why: str) -> Reading:
        """A read that brought no value: every signal NaN, not fresh for ``why``."""
        return Reading(dict.fromkeys(self.reads, math.nan), dict.fromkeys(self.reads, why))

    def _reading(self, data: list[Any]) -> Reading:
        now = time.time()
        out, stale, newest = {}, {}, None
        for signal, dv in zip(self.reads, data, strict=True):
            value = dv.Value.Value if dv.Value is not None else None
            try:
                out[signal] = float(value)
            except (TypeError, ValueError):
                out[signal] = math.nan
            status = dv.StatusCode
            source = dv.SourceTimestamp or dv.ServerTimestamp
            ts = source.replace(tzinfo=source.tzinfo or UTC).timestamp() if source else None
            if status is not None and not status.is_good():
                stale[signal] = f"status {status.name}"
            elif ts is None:
                stale[signal] = "no timestamp"
            elif now - ts > self.max_age:
                stale[signal] = f"{now - ts:.3g} s old"
            elif not math.isfinite(out[signal]):
                stale[signal] = f"value {value!r}"
            if ts is not None and (newest is None or ts > newest):
                newest = ts
        return Reading(out, stale, newest)

    def write(self, values: Mapping[str, float]) -> bool:
        """Write ``values`` (already in the input box) to the inputs; ``False`` when the
        write did not reach the plant (disconnected, refused, no answer)."""
        if not self.connected or not values:
            return False
        from asyncua import ua

        names = list(values)
        dvs = [ua.DataValue(ua.Variant(_as(self._types[n], values[n]), self._types[n]))
               for n in names]
        try:
            self._call(self._client.write_values([self._nodes[n] for n in names], dvs),
                       self.timeout)
        except TimeoutError:
            return False
        except ua.UaStatusCodeError:
            return False
        except Exception:
            self._lost()
            return False
        return True

    # -- losing and finding the connection ---------------------------------------------------
    def _lost(self) -> None:
        self.connected = False
        client, self._client = self._client, None
        if client is not None:
            asyncio.run_coroutine_threadsafe(_quietly(client.disconnect()), self._loop)
        self._start_reconnect()

    def _start_reconnect(self) -> None:
        task = self._reconnecting
        if (task is None or task.done()) and not self._closing:
            self._reconnecting = asyncio.run_coroutine_threadsafe(self._reconnect(), self._loop)

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
        """Disconnect and stop the session's thread; safe to call more than once."""
        if self._closing:
            return
        self._closing = True
        client, self._client = self._client, None
        self.connected = False
        if client is not None:
            with contextlib.suppress(Exception):
                self._call(_quietly(client.disconnect()), 2.0)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(2.0)


async def _walk(start: Any, path: Sequence[tuple[int | None, str]], what: str) -> Any:
    """The node at browse ``path`` below ``start`` (a segment without a namespace index
    matches any)."""
    node = start
    for ns, name in path:
        for child in await node.get_children():
            q = await child.read_browse_name()
            if q.Name == name and (ns is None or q.NamespaceIndex == ns):
                node = child
                break
        else:
            raise CosimError(f"{what}: no node '{name}' below "
                             f"'{(await node.read_browse_name()).Name}'")
    return node


async def _quietly(coro: Any) -> None:
    with contextlib.suppress(Exception):
        await coro


def _variant_type(dtype: Any) -> Any:
    """The variant type to write a node whose DataType is ``dtype`` (Double by default)."""
    from asyncua import ua

    V = ua.VariantType
    numeric = (V.Double, V.Float, V.SByte, V.Byte, V.Int16, V.UInt16, V.Int32, V.UInt32,
               V.Int64, V.UInt64)
    if dtype.NamespaceIndex == 0:
        with contextlib.suppress(ValueError):
            vt = V(dtype.Identifier)
            if vt in numeric:
                return vt
    return V.Double


def _as(vt: Any, value: float) -> Any:
    return float(value) if vt.name in ("Double", "Float") else round(value)


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

