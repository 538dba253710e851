"""The controller's own OPC UA faceplate (``cosim run --faceplate URL``): what the DCS's HMI,
or any OPC UA client, writes to run the controller (issue 61; docs: guide/operating.md).

While a run goes, :class:`Faceplate` serves, below Objects::

    Faceplate/                      ns=urn:gru-mpc-cosim:faceplate
        Mode                        op.mode: 1 auto, 0 manual
        Inputs/<input>/InService    op.service.<input>: 1 / 0
                     /Manual        op.manual.<input>: the operator's value in manual
                     /Min, Max      op.min.<input>, op.max.<input>: operator limits
                     /Value         read-only: the input the plant got (plant.<input>)
                     /Computed      read-only: what the controller computed (ctrl.<input>)
        Outputs/<output>/Control    op.control.<output>: 1 / 0 (a law that lets it go)
                       /Min, Max    op.min.<output>, op.max.<output>
                       /SetPoint    ref.<output>
                       /Predicted   read-only: the outputs the plan predicts over the horizon
                       /PredictionError  read-only: the RMS of the k-step errors so far
        Engineering/<setting>       the engineer's settings (the weights), writable by an
                                    engineer only
        Status/Time                 read-only: the last sample's time
        Status/LastAnswer           read-only: what the last write did, in words

The node ids are the settings' names (``ns=<idx>;s=op.max.h1``): one name with the scenario
columns and ``operator.csv``. Every write goes through the run's
:class:`cosim.core.operator.OperatorDesk`, checked exactly as a scenario row and recorded as
one row of ``operator.csv`` (who: the user): a value outside the setting's range, or one the
controller refuses (its certificate cannot cover it), answers ``BadOutOfRange``; a setting
not the user's role's answers ``BadUserAccessDenied``; the node then keeps the setting in
force. Users and roles come from a users file (``--faceplate-users``: an ``operator`` may
change the mode, the services, the limits and the set-points, an ``engineer`` also the
weights), each password from the environment variable its entry names (never the command
line); without one the faceplate is read-only. The connection's security is the run's
(``--security``, ``--certificate``, ``--private-key``, ``--trust``: the plant's).

The server runs in a thread of its own, with its own event loop; it is started before the
run's first step and stopped when the run ends (bounded: :data:`START_TIMEOUT`,
:data:`STOP_TIMEOUT`).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError
from cosim.live.security import Security

__all__ = ["NAMESPACE", "START_TIMEOUT", "STOP_TIMEOUT", "Faceplate", "FaceplateOptions",
           "read_users"]

#: The faceplate's namespace.
NAMESPACE = "urn:gru-mpc-cosim:faceplate"
#: The application URI of the faceplate server (its certificate must carry it).
APPLICATION_URI = "urn:gru-mpc-cosim:faceplate"
#: Longest wait for the server to listen, and for it to stop [s].
START_TIMEOUT, STOP_TIMEOUT = 30.0, 10.0
#: The browse names of the operator's settings, by family.
_NAMES = {"service": "InService", "manual": "Manual", "control": "Control", "min": "Min",
          "max": "Max"}


@dataclass(frozen=True)
class FaceplateOptions:
    """Where and for whom the faceplate is served: ``endpoint`` (``opc.tcp://host:port``),
    ``users`` (name → ``(role, password)``) and the connection's ``security``."""

    endpoint: str
    users: Mapping[str, tuple[str, str]] = field(default_factory=dict)
    security: Security = field(default_factory=Security)

    @classmethod
    def of(cls, endpoint: str, users: str | Path | None, security: Security | None
           ) -> FaceplateOptions:
        """The options of ``--faceplate``, ``--faceplate-users`` and the run's security.

        Raises
        ------
        CosimError
            A bad endpoint or users file (one line naming it).
        """
        from cosim.live.runner import check_endpoint

        check_endpoint(endpoint, "--faceplate")
        return cls(endpoint, read_users(users) if users is not None else {},
                   security or Security())


def read_users(path: str | Path) -> dict[str, tuple[str, str]]:
    """The users of a faceplate users file (TOML)::

        [users.alice]
        role = "operator"              # or "engineer"
        password_env = "FACEPLATE_ALICE"   # the environment variable holding the password

    Raises
    ------
    CosimError
        A missing or malformed file, an unknown role, a password variable not set (one
        line naming the file and user).
    """
    from cosim.core.operator import ROLES, users_table

    path = Path(path)
    table = users_table(path, "--faceplate-users", "role and password_env")
    out = {}
    for name, entry in table.items():
        where = f"{path}: [users.{name}]"
        if not isinstance(entry, dict) or set(entry) != {"role", "password_env"}:
            raise CosimError(f"{where}: expected exactly role and password_env")
        if entry["role"] not in ROLES:
            raise CosimError(f"{where}: role {entry['role']!r}: expected "
                             f"{' or '.join(map(repr, ROLES))}")
        password = os.environ.get(str(entry["password_env"]))
        if not password:
            raise CosimError(f"{where}: the environment variable {entry['password_env']} "
                             "holding the password is not set")
        out[str(name)] = (str(entry["role"]), password)
    return out


class Faceplate:
    """The faceplate of one run (module docstring).

    Parameters
    ----------
    desk : OperatorDesk
        The run's operator desk (:attr:`cosim.core.master.Master.desk`).
    controller : Component
        The run's controller (its predictions: :meth:`Component.operator_status`).
    options : FaceplateOptions
    notice : callable
        Takes the server's one-line messages.
    """

    def __init__(self, desk: Any, controller: Any, options: FaceplateOptions,
                 notice: Callable[[str], None] = print) -> None:
        self.desk, self.controller, self.options = desk, controller, options
        self.notice = notice
        self._nodes: dict[str, Any] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None

    # -- the thread --------------------------------------------------------------------------
    def start(self) -> None:
        """Serve from a thread of its own; returns once the server listens.

        Raises
        ------
        CosimError
            It could not listen within :data:`START_TIMEOUT` seconds (why, one line).
        """
        self._thread = threading.Thread(target=self._run, name="faceplate", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT) or self._error is not None:
            self.stop()
            why = self._error or f"not listening after {START_TIMEOUT:g} s"
            raise CosimError(f"--faceplate {self.options.endpoint}: cannot serve: {why}")
        self.desk.listeners.append(self._sampled)

    def stop(self) -> None:
        """Stop the server (bounded by :data:`STOP_TIMEOUT`); idempotent."""
        with contextlib.suppress(ValueError):
            self.desk.listeners.remove(self._sampled)
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(stop.set)
        if self._thread is not None:
            self._thread.join(STOP_TIMEOUT)
            self._thread = None

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:   # reported by start(); a later one ends the thread
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        from cosim.live import quiet_libraries

        quiet_libraries()
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        server = await self._server()
        async with server:
            if not self.options.security.secure:
                self.notice("faceplate: warning: no security: anyone who reaches "
                            f"{self.options.endpoint} can read it"
                            + (" and write it" if self.options.users else ""))
            self.notice(f"faceplate: serving at {self.options.endpoint}"
                        + ("" if self.options.users else " (read-only: no users)"))
            self._ready.set()
            await self._stop.wait()

    # -- the server --------------------------------------------------------------------------
    async def _server(self) -> Any:
        from asyncua import Server

        from cosim.live.security import secure_server

        users = _Users(self.options.users) if self.options.users else None
        server = Server(user_manager=users)
        await server.init()
        server.set_endpoint(self.options.endpoint)
        server.set_server_name("cosim run: the controller's faceplate")
        await server.set_application_uri(APPLICATION_URI)
        await secure_server(server, self.options.security, users is not None)
        await self._address_space(server)
        service = server.iserver.attribute_service
        original = service.write

        async def write(params: Any, user: Any = None) -> list[Any]:
            return await self._write(original, params, user)

        service.write = write
        return server

    async def _address_space(self, server: Any) -> None:
        from asyncua import ua

        idx = await server.register_namespace(NAMESPACE)
        self.idx = idx
        root = await server.nodes.objects.add_folder(ua.NodeId("Faceplate", idx),
                                                     ua.QualifiedName("Faceplate", idx))
        folders: dict[str, Any] = {}

        async def folder(path: str) -> Any:
            if path not in folders:
                parent_path, _, name = path.rpartition("/")
                parent = await folder(parent_path) if parent_path else root
                folders[path] = await parent.add_folder(
                    ua.NodeId(f"Faceplate/{path}", idx), ua.QualifiedName(name, idx))
            return folders[path]

        inputs = {s.name for s in self.controller.outputs}
        for name in self.desk.catalog:
            where, browse = _place(name, inputs)
            parent = await folder(where) if where else root
            await self._variable(parent, name, browse, self.desk.value(name), True)
        ctrl = self.controller
        for s in ctrl.outputs:
            parent = await folder(f"Inputs/{s.name}")
            await self._variable(parent, f"plant.{s.name}", "Value", math.nan, False)
            await self._variable(parent, f"ctrl.{s.name}", "Computed", math.nan, False)
        for y in (s.name[len("ref."):] for s in ctrl.inputs if s.name.startswith("ref.")):
            parent = await folder(f"Outputs/{y}")
            await self._variable(parent, f"pred.{y}", "Predicted", [math.nan], False)
            await self._variable(parent, f"prediction_error.{y}", "PredictionError",
                                 math.nan, False)
        status = await folder("Status")
        await self._variable(status, "time", "Time", math.nan, False)
        await self._variable(status, "answer", "LastAnswer", "", False)

    async def _variable(self, parent: Any, ident: str, browse: str, value: Any,
                        writable: bool) -> None:
        from asyncua import ua

        variant = _variant(value)
        node = await parent.add_variable(ua.NodeId(ident, self.idx),
                                         ua.QualifiedName(browse, self.idx), variant)
        if writable:
            await node.set_writable()
        self._nodes[ident] = node

    # -- writes and status -------------------------------------------------------------------
    async def _write(self, original: Callable[..., Any], params: Any, user: Any) -> list[Any]:
        """The server's writes: those on the faceplate's settings through the desk (one
        answer each), any other as the server does them."""
        from asyncua import ua
        from asyncua.crypto.permission_rules import UserRole

        internal = user is None or user.role == UserRole.Admin   # the server's own writes
        if internal:
            return await (original(params) if user is None else original(params, user))
        results = []
        loop = asyncio.get_running_loop()
        for item in params.NodesToWrite:
            ident = item.NodeId.Identifier
            if ident not in self.desk.catalog or item.NodeId.NamespaceIndex != self.idx:
                results += await original(ua.WriteParameters(NodesToWrite=[item]), user)
                continue
            name = getattr(user, "name", None)
            role = self.options.users.get(name, ("", ""))[0] if name else ""
            value = item.Value.Value.Value if item.Value.Value is not None else None
            answer = await loop.run_in_executor(None, self.desk.act, self.desk.t,
                                                name or "anonymous", ident, value,
                                                role or "nobody")
            await self._set(ident, self.desk.value(ident))
            await self._set("answer", f"{ident}: {answer.text}")
            code = (ua.StatusCodes.Good if answer.accepted else
                    ua.StatusCodes.BadUserAccessDenied if answer.denied
                    else ua.StatusCodes.BadOutOfRange)
            results.append(ua.StatusCode(code))
        return results

    async def _set(self, ident: str, value: Any) -> None:
        from asyncua import ua

        await self._nodes[ident].write_value(ua.DataValue(_variant(value)))

    def _sampled(self, desk: Any) -> None:
        """After each of the run's samples (the loop's thread): the status, published."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        status = self.controller.operator_status() or {}
        values: dict[str, Any] = {"time": desk.t}
        values.update({f"plant.{u}": v for u, v in desk.applied.items()})
        values.update({f"ctrl.{u}": v for u, v in desk.computed.items()})
        for y, pred in (status.get("prediction") or {}).items():
            values[f"pred.{y}"] = list(pred) or [math.nan]
        for y, err in (status.get("prediction_error") or {}).items():
            values[f"prediction_error.{y}"] = math.nan if err is None else err
        values.update({name: desk.value(name) for name in desk.catalog})
        with contextlib.suppress(RuntimeError):
            asyncio.run_coroutine_threadsafe(self._publish(values), loop)

    async def _publish(self, values: dict[str, Any]) -> None:
        for ident, value in values.items():
            if ident in self._nodes:
                await self._set(ident, value)


def _place(name: str, inputs: set[str]) -> tuple[str, str]:
    """The folder and browse name of setting ``name`` (module docstring; ``inputs``: the
    controller's inputs to the plant)."""
    if name == "op.mode":
        return "", "Mode"
    if name.startswith("ref."):
        return f"Outputs/{name[len('ref.'):]}", "SetPoint"
    parts = name.split(".")
    if parts[0] == "op" and len(parts) == 3 and parts[1] in _NAMES:
        side = "Inputs" if parts[2] in inputs else "Outputs"
        return f"{side}/{parts[2]}", _NAMES[parts[1]]
    return "Engineering", name


class _Users:
    """A user manager that accepts the users file's users with their passwords."""

    def __init__(self, users: Mapping[str, tuple[str, str]]) -> None:
        self.users = dict(users)

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        entry = self.users.get(username or "")
        if entry is not None and password == entry[1]:
            return User(role=UserRole.User, name=username)
        return None


def _variant(value: Any) -> Any:
    """A faceplate value as an OPC UA variant: a list of doubles, a string or a double."""
    from asyncua import ua

    if isinstance(value, list):
        return ua.Variant([float(v) for v in value], ua.VariantType.Double)
    if isinstance(value, str):
        return ua.Variant(value, ua.VariantType.String)
    return ua.Variant(float(value), ua.VariantType.Double)
