"""The page's web server: a Bokeh server in a thread of its own, its address and its login.

:class:`PageServer` serves Bokeh applications (a run's page, a campaign's) at
``http://HOST:PORT/`` from a thread with its own event loop, so that the run's loop never
waits for it; every script and style comes from the server itself (BokehJS from the bokeh
wheel, nothing from a CDN). Updates travel over the session's websocket.

Writing needs a login: ``/login`` checks a name and password against the users file
(:class:`cosim.hmi.users.Users`) and sets a signed cookie that the page reads when it opens
(:func:`session_user`). Viewing needs none on the loopback interface; on any other address the
page itself is behind the login, and a server without users refuses to start there.

:func:`parse_address` reads ``[HOST:]PORT`` (loopback unless a host is given); a port in use
or an address that cannot be listened on is a one-line :class:`~cosim.core.errors.CosimError`
naming the flag (exit 2) before anything runs.
"""

from __future__ import annotations

import asyncio
import html
import ipaddress
import logging
import secrets
import threading
from collections.abc import Callable, Mapping
from typing import Any

from cosim.core.errors import CosimError
from cosim.hmi.actions import User
from cosim.hmi.users import Users

__all__ = ["COOKIE", "LOOPBACK", "PageServer", "parse_address", "session_user"]

#: Where the page is served unless a host is given.
LOOPBACK = "127.0.0.1"
#: The signed cookie that holds a logged-in user (``name:role``).
COOKIE = "cosim_hmi_user"
#: Seconds the server may take to start listening.
START_TIMEOUT = 30.0


def parse_address(text: str, flag: str = "--hmi") -> tuple[str, int]:
    """``(host, port)`` of ``[HOST:]PORT`` (host :data:`LOOPBACK` when not given).

    Raises
    ------
    CosimError
        Not ``[HOST:]PORT`` with a port in 1 … 65535.
    """
    host, sep, port = str(text).rpartition(":")
    host = host.strip("[]") if sep else LOOPBACK
    if not port.isdigit() or not 0 < int(port) < 65536 or (sep and not host):
        raise CosimError(f"{flag} {text}: expected [HOST:]PORT with a port in 1 ... 65535 "
                         "(e.g. 8050 or 0.0.0.0:8050)")
    return host, int(port)


def is_loopback(host: str) -> bool:
    """Whether ``host`` is the loopback interface."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def session_user(doc: Any, secret: bytes) -> User | None:
    """The logged-in user of a page's session (its signed cookie), else ``None``."""
    from tornado.web import decode_signed_value

    context = doc.session_context
    request = getattr(context, "request", None) if context is not None else None
    raw = (getattr(request, "cookies", None) or {}).get(COOKIE)
    if not raw:
        return None
    value = decode_signed_value(secret, COOKIE, raw, max_age_days=1)
    if not value:
        return None
    name, _, role = value.decode().rpartition(":")
    return User(name, role) if name else None


def _auth(users: Users | None, secret: bytes, open_view: bool) -> Any:
    """The Bokeh auth provider: ``/login`` and ``/logout``; viewing without a login when
    ``open_view``."""
    from bokeh.server.auth_provider import AuthProvider
    from tornado.web import RequestHandler

    class Login(RequestHandler):
        def get(self) -> None:
            self.write(_login_form(self.get_argument("next", "/"), ""))

        def post(self) -> None:
            name = self.get_argument("name", "")
            user = users.check(name, self.get_argument("password", "")) if users else None
            target = self.get_argument("next", "/")
            if user is None:
                self.set_status(403)
                self.write(_login_form(target, "wrong name or password"))
                return
            self.set_signed_cookie(COOKIE, f"{user.name}:{user.role}", expires_days=1,
                                   httponly=True, samesite="Strict")
            self.redirect(target if target.startswith("/") else "/")

    class Logout(RequestHandler):
        def get(self) -> None:
            self.clear_cookie(COOKIE)
            self.redirect("/")

    class Provider(AuthProvider):
        def get_user(self, handler: Any) -> Any:   # type: ignore[override]
            value = handler.get_signed_cookie(COOKIE, max_age_days=1)
            return value.decode() if value else ("-" if open_view else None)

        login_url = "/login"
        login_handler = Login
        logout_url = "/logout"
        logout_handler = Logout

    return Provider()


def _login_form(target: str, error: str) -> str:
    """The login page: a plain form, no script."""
    note = f'<p class="error">{html.escape(error)}</p>' if error else ""
    return (f"<!doctype html><html><head><title>cosim · log in</title></head><body>"
            f"<h1>Log in to operate</h1>{note}<form method=post action=/login>"
            f'<input type=hidden name=next value="{html.escape(target)}">'
            f"<label>name <input name=name autocomplete=username></label> "
            f"<label>password <input name=password type=password "
            f"autocomplete=current-password></label> <button type=submit>Log in</button>"
            f"</form></body></html>")


class PageServer:
    """Bokeh applications served from a thread (module docstring).

    Parameters
    ----------
    pages : mapping of str to callable
        URL path → ``make(doc, user, secret)`` that fills a session's document.
    host, port : str, int
        Where to listen (:func:`parse_address`).
    users : Users, optional
        Who may log in; without them nobody writes (and only the loopback interface
        serves).
    flag : str
        The option that named the address (quoted in errors).
    """

    def __init__(self, pages: Mapping[str, Callable[[Any, User | None, bytes], None]],
                 host: str, port: int, users: Users | None = None, flag: str = "--hmi") -> None:
        if not is_loopback(host) and users is None:
            raise CosimError(f"{flag} {host}:{port}: a page on an address other than the "
                             "loopback interface needs a login: give --hmi-users")
        self.pages = dict(pages)
        self.host, self.port, self.users, self.flag = host, port, users, flag
        self.secret = secrets.token_bytes(32)
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._ready = threading.Event()

    @property
    def url(self) -> str:
        """The page's address."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def start(self) -> PageServer:
        """Listen and serve in a daemon thread; returns once it listens.

        Raises
        ------
        CosimError
            The address cannot be listened on (a port in use, an unknown host).
        """
        for name in ("bokeh", "tornado.access", "tornado.application", "tornado.general"):
            logging.getLogger(name).setLevel(logging.ERROR)
        self._thread = threading.Thread(target=self._serve, name="cosim-hmi", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            raise CosimError(f"{self.flag} {self.host}:{self.port}: the page's server did not "
                             f"start within {START_TIMEOUT:g} s")
        if self._error is not None:
            error = self._error
            why = getattr(error, "strerror", None) or str(error)
            raise CosimError(f"{self.flag} {self.host}:{self.port}: cannot listen: {why}")
        return self

    def _serve(self) -> None:
        from bokeh.application import Application
        from bokeh.application.handlers.function import FunctionHandler
        from bokeh.server.server import Server
        from tornado.ioloop import IOLoop

        asyncio.set_event_loop(asyncio.new_event_loop())
        apps = {path: Application(FunctionHandler(self._maker(make)))
                for path, make in self.pages.items()}
        origins = [f"{self.host}:{self.port}"]
        if is_loopback(self.host):
            origins += [f"localhost:{self.port}", f"127.0.0.1:{self.port}"]
        try:
            server = Server(apps, io_loop=IOLoop.current(), address=self.host, port=self.port,
                            allow_websocket_origin=origins, use_index=False,
                            auth_provider=_auth(self.users, self.secret,
                                                is_loopback(self.host)),
                            cookie_secret=self.secret, secret_key=self.secret,
                            sign_sessions=True, include_cookies=[COOKIE],
                            check_unused_sessions_milliseconds=2000,
                            unused_session_lifetime_milliseconds=5000)
            server.start()
        except Exception as exc:   # reported to the caller's thread
            self._error = exc
            self._ready.set()
            return
        self._server = server
        self._ready.set()
        server.io_loop.start()
        server.io_loop.close(all_fds=True)

    def _maker(self, make: Callable[[Any, User | None, bytes], None]) -> Callable[[Any], None]:
        secret = self.secret

        def modify(doc: Any) -> None:
            make(doc, session_user(doc, secret), secret)

        return modify

    def stop(self) -> None:
        """Stop serving and end the thread (idempotent)."""
        server, self._server = self._server, None
        thread, self._thread = self._thread, None
        if server is not None:
            loop = server.io_loop

            def end() -> None:
                server.stop(wait=False)
                loop.stop()

            loop.add_callback(end)
        if thread is not None:
            thread.join(10.0)

    def __enter__(self) -> PageServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
