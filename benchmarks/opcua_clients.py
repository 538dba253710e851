"""The OPC UA clients that ``bench_opcua_client.py`` measures, each connected to a plant
(:class:`Plant`) with its own session and reading (:meth:`read`: one Read service call of the
outputs) and writing (:meth:`write`: one Write call of the inputs) as a sample does:
asyncua through ``cosim.live.session.PlantSession`` (:class:`SessionClient`), asyncua with its
requests built once (:class:`AsyncuaPrebuilt`), o6 (open62541, :class:`O6Client`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

READS, WRITES = ("h1", "h2"), ("qa", "qb")
START = {"qa": 4.5472443083696316e-4, "qb": 5.523354343150548e-4}
USER = "bench"
#: o6 DateTime ticks (100 ns since 1601) at the Unix epoch.
EPOCH_TICKS = 116444736000000000


@dataclass
class Plant:
    """A running server: endpoint, node ids of the reads and writes, the client's security
    (with its root folder for a tags file), and how to stop it."""

    name: str
    endpoint: str
    ids: dict[str, str]
    security: Any
    root: tuple
    stop: Callable[[], Any]
    restart: Callable[[], Any] | None = None


@dataclass
class Answer:
    """What a client read: values, whether every status was Good, the newest source time."""

    values: tuple[float, ...]
    good: bool
    source_time: float


class SessionClient:
    """``cosim.live.session.PlantSession`` as ``cosim run`` uses it."""

    name = "session"

    def __init__(self, plant: Plant) -> None:
        from controllers.problem_file import load
        from cosim.core.build import DEFAULT_PROBLEM
        from cosim.live.session import PlantSession
        from cosim.live.tags import Tag, Tags

        tags = Tags(root=plant.root, tags={s: Tag(node_id=plant.ids[s]) for s in plant.ids})
        self.session = PlantSession(plant.endpoint, reads=READS, writes=WRITES, tags=tags,
                                    folder="fourtank", security=plant.security,
                                    max_age=1e9, timeout=5.0,
                                    units=load(DEFAULT_PROBLEM).units())
        self.session.connect()

    def read(self) -> Answer:
        r = self.session.read()
        return Answer(tuple(r.values[s] for s in READS), r.fresh, r.source_time or 0.0)

    def write(self, values: tuple[float, ...]) -> None:
        failed = self.session.write(dict(zip(WRITES, values, strict=True)))
        if failed:
            raise RuntimeError(f"session: the write did not reach the plant: {failed}")

    def close(self) -> None:
        self.session.close()


class AsyncuaPrebuilt:
    """asyncua with its Read and Write parameters built once; on a loop of its own thread
    (``inline=False``, the session's design) or of the calling thread."""

    def __init__(self, plant: Plant, inline: bool, reads: tuple[str, ...] = READS) -> None:
        from asyncua import ua

        self.name = "asyncua-inline" if inline else "asyncua-prebuilt"
        self.loop = asyncio.new_event_loop()
        self.thread = None
        if not inline:
            self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
            self.thread.start()
        self.plant = plant
        self.client = self.call(asyncua_client(plant))
        value = ua.AttributeIds.Value
        self.rparams = ua.ReadParameters(
            TimestampsToReturn=ua.TimestampsToReturn.Both,
            NodesToRead=[ua.ReadValueId(NodeId=ua.NodeId.from_string(plant.ids[s]),
                                        AttributeId=value) for s in reads])
        self.wparams = ua.WriteParameters(NodesToWrite=[
            ua.WriteValue(NodeId=ua.NodeId.from_string(plant.ids[s]), AttributeId=value,
                          Value=ua.DataValue(ua.Variant(0.0, ua.VariantType.Double)))
            for s in WRITES])
        self.variants = [w.Value.Value for w in self.wparams.NodesToWrite]

    def call(self, coro: Any) -> Any:
        if self.thread is None:
            return self.loop.run_until_complete(asyncio.wait_for(coro, 5.0))
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(5.0)

    def read(self) -> Answer:
        data = self.call(self.client.uaclient.read(self.rparams))
        good, newest = True, 0.0
        for dv in data:
            good = good and (dv.StatusCode is None or dv.StatusCode.is_good())
            ts = dv.SourceTimestamp or dv.ServerTimestamp
            newest = max(newest, ts.timestamp() if ts is not None else 0.0)
        return Answer(tuple(float(dv.Value.Value) for dv in data), good, newest)

    def write(self, values: tuple[float, ...]) -> None:
        for variant, v in zip(self.variants, values, strict=True):
            variant.Value = float(v)
        for status in self.call(self.client.uaclient.write(self.wparams)):
            status.check()

    def reconnect(self) -> None:
        """A new connection (asyncua does not reconnect by itself)."""
        with contextlib.suppress(Exception):
            self.call(self.client.disconnect())
        self.client = self.call(asyncua_client(self.plant))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.call(self.client.disconnect())
        if self.thread is not None:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(2.0)


async def asyncua_client(plant: Plant) -> Any:
    """An asyncua client connected as ``PlantSession`` connects (security, user)."""
    from asyncua import Client, ua
    from asyncua.crypto import security_policies

    from cosim.live.session import APPLICATION_URI

    client = Client(plant.endpoint, timeout=5.0)
    client.application_uri = APPLICATION_URI
    sec = plant.security
    if sec.secure:
        await client.set_security(getattr(security_policies, f"SecurityPolicy{sec.policy}"),
                                  str(sec.certificate), str(sec.private_key),
                                  server_certificate=str(sec.trust[0]),
                                  mode=getattr(ua.MessageSecurityMode, sec.mode))
    if sec.user is not None:
        client.set_user(sec.user)
        client.set_password(sec.password or "")
    await client.connect()
    return client


def o6_module() -> Any:
    """o6, imported from the environment or from ``.o6/``; ``None`` where it is not."""
    try:
        import o6
    except ImportError:
        if not (ROOT / ".o6" / "o6").is_dir():
            return None
        sys.path.insert(0, str(ROOT / ".o6"))
        import o6
    return o6


#: cosim's security policies (asyncua's names) as o6's.
O6_POLICIES: dict[str, Any] = {}


class O6Client:
    """o6's synchronous client (its own worker thread); ``prebuilt``: the Read and Write
    requests built once and sent by ``serviceRead``/``serviceWrite``."""

    def __init__(self, plant: Plant, prebuilt: bool) -> None:
        o6 = self.o6 = o6_module()
        from o6.ns import ns0

        O6_POLICIES.update(Basic256Sha256=o6.SecurityPolicy.BASIC256SHA256,
                           Aes128Sha256RsaOaep=o6.SecurityPolicy.AES128_SHA256_RSAOAEP,
                           Aes256Sha256RsaPss=o6.SecurityPolicy.AES256_SHA256_RSAPSS)
        from cosim.live.session import APPLICATION_URI

        sec = plant.security
        options: dict[str, Any] = {"applicationUri": APPLICATION_URI}
        if sec.secure:
            # the policy's URI: o6 2.2.0 keeps a short name as it is, and then finds no
            # endpoint ("BadIdentityTokenRejected")
            options.update(certificate=str(sec.certificate), privateKey=str(sec.private_key),
                           trustList=[str(p) for p in sec.trust],
                           securityPolicy=O6_POLICIES[sec.policy].value,
                           securityMode=getattr(o6.SecurityMode, {
                               "Sign": "SIGN", "SignAndEncrypt": "SIGN_AND_ENCRYPT"}[sec.mode]))
        if sec.user is not None:
            options.update(username=sec.user, password=sec.password or "")
        self.name = "o6-prebuilt" if prebuilt else "o6"
        quiet = logging.getLogger("bench_opcua_client.o6")
        quiet.setLevel(logging.CRITICAL)
        self.client = o6.Client(plant.endpoint, logger=quiet, **options)
        self.client.loop.set_exception_handler(lambda loop, context: None)
        self.client.config.timeout = 5000
        self.client.connect(createDefaultSubscription=False)
        self.reads = [o6.NodeId(plant.ids[s]) for s in READS]
        self.writes = [o6.NodeId(plant.ids[s]) for s in WRITES]
        self.prebuilt = prebuilt
        if prebuilt:
            self.rreq = ns0.datatypes.ReadRequest()
            self.rreq.timestampsToReturn = ns0.datatypes.TimestampsToReturn.BOTH
            items = []
            for nid in self.reads:
                item = ns0.datatypes.ReadValueId()
                item.nodeId, item.attributeId = nid, o6.AttributeId.VALUE
                items.append(item)
            self.rreq.nodesToRead = items
            self.wreq = ns0.datatypes.WriteRequest()

    def read(self) -> Answer:
        if self.prebuilt:
            response = self.client.serviceRead(self.rreq)
            response.responseHeader.serviceResult.check(message="Read service")
            data = list(response.results)
        else:
            data = self.client.read(self.reads, valueOnly=False)
        good, newest = True, 0.0
        for dv in data:
            good = good and not (dv.status or 0)
            ts = dv.sourceTimestamp or dv.serverTimestamp
            newest = max(newest, (int(ts) - EPOCH_TICKS) / 1e7 if ts is not None else 0.0)
        return Answer(tuple(float(dv.value) for dv in data), good, newest)

    def write(self, values: tuple[float, ...]) -> None:
        o6 = self.o6
        if self.prebuilt:
            from o6.ns import ns0

            items = []
            for nid, v in zip(self.writes, values, strict=True):
                item = ns0.datatypes.WriteValue()
                item.nodeId, item.attributeId = nid, o6.AttributeId.VALUE
                item.value = o6.DataValue(value=o6.Double(v))
                items.append(item)
            self.wreq.nodesToWrite = items
            response = self.client.serviceWrite(self.wreq)
            response.responseHeader.serviceResult.check(message="Write service")
            statuses = list(response.results)
        else:
            statuses = self.client.write(dict(zip(self.writes, map(o6.Double, values),
                                                  strict=True)))
        if any(int(s) for s in statuses):
            raise RuntimeError(f"{self.name}: write refused: {statuses}")

    def reconnect(self) -> None:
        """``disconnect()`` then ``connect()`` (o6 did not reconnect by itself)."""
        with contextlib.suppress(Exception):
            self.client.disconnect()
        self.client.connect(createDefaultSubscription=False)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.disconnect()


def clients_for(plant: Plant, names: list[str]) -> list[Any]:
    """The clients asked for, connected (o6's left out where it is not installed)."""
    makers: dict[str, Callable[[], Any]] = {
        "session": lambda: SessionClient(plant),
        "asyncua-prebuilt": lambda: AsyncuaPrebuilt(plant, inline=False),
        "asyncua-inline": lambda: AsyncuaPrebuilt(plant, inline=True),
        "o6": lambda: O6Client(plant, prebuilt=False),
        "o6-prebuilt": lambda: O6Client(plant, prebuilt=True)}
    out = []
    for name in names:
        if name.startswith("o6") and o6_module() is None:
            print(f"  {name}: left out (o6 is not installed: pip install o6)")
            continue
        out.append(makers[name]())
    return out
