"""A component's native code in a process of its own, which a crash cannot take down and a
timeout can kill.

An FMU is native code (a plant's, a controller's): a segmentation fault, an ``abort()`` or an
``exit()`` inside it would end the runner, results and all, and a call stuck in a loop would
hang it for ever, deaf to Ctrl-C. A :class:`Worker` runs a *server* object, built in a child
process (a fresh interpreter: this process's ``__main__`` is never run again there) from a
``module:Class`` name and keyword arguments, and calls its methods over a socket: one round
trip per call, in small tuples of strings and floats (:mod:`cosim.core.isolated` serves the
FMUs so).

* A call the worker does not answer within :attr:`Worker.timeout` seconds kills the worker
  (SIGKILL) and fails: ``"doStep at t=500.0 took longer than the step timeout of 5 s (worker
  killed)"``.
* A worker that dies during a call (a signal, ``exit()``, killed) fails it with the reason
  and what the worker last printed: ``"doStep at t=50.0 failed: worker died (signal 6,
  SIGABRT); it last printed: 'model.c:12: ctl_step: Assertion ...'"``.
* A signal that interrupts the parent while it waits (Ctrl-C, SIGTERM, SIGHUP: the master's
  :class:`~cosim.core.interrupts.SignalGuard` raises) leaves the worker busy; :meth:`Worker.stop`
  then kills it at once: nothing waits for a hung call.
* The worker ignores those signals and sits in a process group of its own: the parent decides
  when it ends, and a signal the native code sends to its own group never reaches the parent.
  It dies with its parent (``PR_SET_PDEATHSIG`` on Linux). It is a plain child process, not
  a :mod:`multiprocessing` one, so a daemonic process (a Dask worker) may start it too.
* Its standard output and error go into a pipe that a thread of the parent drains, keeping the
  last :data:`OUTPUT_TAIL` bytes: a flood of output costs neither memory nor the terminal,
  and the last line explains a death.
* A scratch folder (``cosim-fmu-*``) that the parent creates and removes, so that nothing is
  left behind however the worker ends.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import json
import os
import select
import shutil
import signal as _signal
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError, SimulationFailed, one_line

__all__ = ["OUTPUT_TAIL", "TERMINATE_WAIT", "Worker"]

#: How long :meth:`Worker.stop` waits for an idle worker to finish its last request, and a
#: dying one to be reaped.
TERMINATE_WAIT = 5.0
#: Bytes of the worker's standard output and error kept (the rest is read and dropped).
OUTPUT_TAIL = 4096
#: Longest quote of the worker's last output in a message.
LAST_WORDS = 200
_PR_SET_PDEATHSIG = 1


#: What the child interpreter runs: the parent's import path first, then :func:`_main` with
#: its socket's file descriptor and the parent's process id.
_BOOT = ("import json, sys; sys.path[:0] = json.loads(sys.argv[3]); "
         "from cosim.core.worker import _main; _main(int(sys.argv[1]), int(sys.argv[2]))")


def _detach(parent: int) -> None:  # pragma: no cover - runs in the child process
    """Make this process a worker: it dies with its parent and ignores the signals the
    parent handles (the parent kills it)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, _signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:   # the parent died before the line above
        os._exit(1)
    for sig in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
        _signal.signal(sig, _signal.SIG_IGN)


def _build(server: str, kwargs: dict[str, Any]) -> Any:  # pragma: no cover - child process
    module, _, name = server.partition(":")
    return getattr(importlib.import_module(module), name)(**kwargs)


def _main(fd: int, parent: int) -> None:  # pragma: no cover - child process
    """The worker's loop on the socket ``fd``: first ``(server, kwargs)``, then
    ``(method, *args)`` requests answered ``("ok", result)`` or ``(kind, message)``
    (``"error"``: a :class:`CosimError`, bad input; ``"failed"``: anything else);
    ``("stop",)`` ends it."""
    from multiprocessing.connection import Connection

    _detach(parent)
    conn = Connection(fd)
    try:
        server, kwargs = conn.recv()
        obj, broken = _build(server, kwargs), None
    except CosimError as exc:
        obj, broken = None, ("error", str(exc))
    except Exception as exc:
        obj, broken = None, ("failed", f"{type(exc).__name__}: {exc}")
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            break
        op = msg[0]
        if op == "stop":
            with contextlib.suppress(Exception):
                obj.close()
            with contextlib.suppress(OSError):
                conn.send(("ok", None))
            break
        try:
            if broken is not None:
                reply: tuple = broken
            elif op.startswith("_") or not callable(getattr(obj, op, None)):
                reply = ("failed", f"unknown request {op!r}")
            else:
                reply = ("ok", getattr(obj, op)(*msg[1:]))
        except SimulationFailed as exc:
            reply = ("failed", str(exc))
        except CosimError as exc:
            reply = ("error", str(exc))
        except Exception as exc:
            reply = ("failed", f"{type(exc).__name__}: {exc}")
        try:
            conn.send(reply)
        except (OSError, ValueError):
            break
    conn.close()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    # skip interpreter teardown: native libraries stay loaded and some (embedded
    # interpreters, static destructors) do not survive it; nothing is left to flush
    os._exit(0)


class _Tail:
    """Drains a pipe (its file descriptor ``reader``) in a daemon thread, keeping its last
    :data:`OUTPUT_TAIL` bytes; closes it at the end."""

    def __init__(self, reader: int) -> None:
        self._reader = reader
        self._data = bytearray()
        self._lock = threading.Lock()
        self.total = 0
        self._thread = threading.Thread(target=self._drain, name="cosim-worker-output",
                                        daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        fd = self._reader
        while True:
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                break
            if not chunk:
                break
            with self._lock:
                self.total += len(chunk)
                self._data += chunk
                del self._data[:-OUTPUT_TAIL]
        with contextlib.suppress(OSError):
            os.close(fd)

    def last_line(self, wait: float = 1.0) -> str:
        """The last non-blank line written (once the writer has closed the pipe, or after
        ``wait`` seconds), control characters escaped, at most :data:`LAST_WORDS`
        characters; ``""`` when nothing was written."""
        self._thread.join(wait)
        with self._lock:
            text = bytes(self._data).decode("utf-8", "replace")
        lines = [ln for ln in text.splitlines() if ln.strip()]
        if not lines:
            return ""
        line = one_line(lines[-1].strip())
        return line if len(line) <= LAST_WORDS else line[:LAST_WORDS - 3] + "..."


class Worker:
    """A server object in a child process (module docstring).

    Parameters
    ----------
    label : str
        Names what the worker runs in messages (``"Hostile.fmu"``).
    server : str
        ``"module:Class"`` of the server; built in the worker with ``kwargs``.
    kwargs : dict
        Keyword arguments of the server (picklable); ``scratch`` (when true) is replaced by
        the path of the scratch folder.
    timeout : float or None
        Wall-clock limit [s] of every call; ``None``: wait for ever.
    scratch : bool
        Create a scratch folder for the worker (removed by :meth:`stop`) and pass its path
        as the server's ``scratch`` argument.
    """

    def __init__(self, label: str, server: str, kwargs: dict[str, Any],
                 timeout: float | None = None, scratch: bool = False) -> None:
        self.label = label
        self.server = server
        self.kwargs = dict(kwargs)
        self.timeout = timeout
        self.scratch = scratch
        self._proc: Any = None
        self._conn: Any = None
        self._poller: Any = None
        self._tail: _Tail | None = None
        self._folder: Path | None = None
        self.busy = False

    @property
    def pid(self) -> int | None:
        """The worker's process id (``None`` when none runs)."""
        return self._proc.pid if self._proc is not None else None

    @property
    def alive(self) -> bool:
        """Whether the worker was started and not stopped."""
        return self._conn is not None

    def start(self) -> None:
        """Start the worker process; the server is built there (a failure to build it
        answers every call).

        Raises
        ------
        CosimError
            The worker process cannot be started (no process left, no memory), or its
            arguments cannot be sent to it (not picklable).
        """
        from multiprocessing.connection import Connection

        self.stop()
        kwargs = dict(self.kwargs)
        if self.scratch:
            self._folder = Path(tempfile.mkdtemp(prefix="cosim-fmu-"))
            kwargs["scratch"] = str(self._folder)
        ours, theirs = socket.socketpair()
        reader, writer = os.pipe()
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-c", _BOOT, str(theirs.fileno()), str(os.getpid()),
                 json.dumps(sys.path)],
                stdin=subprocess.DEVNULL, stdout=writer, stderr=writer,
                pass_fds=(theirs.fileno(),), process_group=0)
        except OSError as exc:
            ours.close()
            os.close(reader)
            self.kill()
            raise CosimError(f"{self.label}: cannot start its worker process: "
                             f"{exc.strerror or exc}") from None
        finally:
            theirs.close()
            os.close(writer)
        self._conn = Connection(ours.detach())
        self._poller = select.poll()   # made once: a call waits with one system call
        self._poller.register(self._conn.fileno(), select.POLLIN)
        self._tail = _Tail(reader)
        try:
            self._conn.send((self.server, kwargs))
        except Exception as exc:   # an option that cannot travel (a function, a lock)
            self.kill()
            raise CosimError(f"{self.label}: its arguments cannot be sent to its worker "
                             f"process: {type(exc).__name__}: {exc}") from None

    def call(self, what: str, method: str, *args: Any) -> Any:
        """The server's ``method(*args)``; ``what`` names the call in messages.

        Raises
        ------
        SimulationFailed
            The call took longer than :attr:`timeout` (the worker is killed), the worker died
            (its exit status or signal and its last output named), or the server raised.
        CosimError
            The server raised a :class:`CosimError` (bad input).
        """
        conn = self._conn
        if conn is None:
            raise SimulationFailed(f"{self.label}: {what} failed: no worker")
        try:
            self.busy = True
            conn.send((method, *args))
            if self.timeout is not None and not self._poller.poll(1e3 * self.timeout):
                self.kill()
                raise SimulationFailed(f"{self.label}: {what} took longer than the step "
                                       f"timeout of {self.timeout:g} s (worker killed)")
            kind, result = conn.recv()
            self.busy = False
        except (EOFError, BrokenPipeError, ConnectionResetError, OSError):
            why = self._death()
            raise SimulationFailed(f"{self.label}: {what} failed: {why}") from None
        if kind == "ok":
            return result
        if kind == "error":
            raise CosimError(result)
        raise SimulationFailed(result)

    def _death(self) -> str:
        """Why the worker is gone (after a broken pipe), with its last output; cleans up."""
        proc, tail = self._proc, self._tail
        code = None
        if proc is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=TERMINATE_WAIT)
            code = proc.returncode
        words = tail.last_line() if tail is not None else ""
        self.kill()
        if code is not None and code < 0:
            try:
                name = _signal.Signals(-code).name
            except ValueError:
                name = "unknown"
            why = f"worker died (signal {-code}, {name})"
        elif code is None:
            why = "worker stopped answering (its pipe closed)"
        else:
            why = f"worker died (exit code {code})"
        return f"{why}; it last printed: {words!r}" if words else why

    def kill(self) -> None:
        """Kill the worker now and remove its scratch folder (idempotent)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.close()
        proc, self._proc = self._proc, None
        if proc is not None:
            if proc.poll() is None:
                with contextlib.suppress(OSError):
                    proc.kill()
            proc.wait()
        self.busy = False
        self._tail = None
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None

    def stop(self) -> None:
        """End the worker (idempotent): an idle one is asked to close its server and given
        :data:`TERMINATE_WAIT` seconds; a busy one (a call was interrupted) is killed at
        once."""
        conn = self._conn
        if conn is not None and not self.busy:
            try:
                conn.send(("stop",))
                if conn.poll(TERMINATE_WAIT):
                    conn.recv()
            except (EOFError, OSError):
                pass
            proc = self._proc
            if proc is not None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=TERMINATE_WAIT)
        self.kill()

    def output_bytes(self) -> int:
        """Bytes the worker has written to its standard output and error so far."""
        return self._tail.total if self._tail is not None else 0
