"""An :class:`~cosim.core.fmu.FmuComponent` whose native code runs in a worker process.

An FMU is native code: a segmentation fault inside ``doStep`` would take the whole runner
down with it, results and all, and a ``doStep`` stuck in a loop would hang it for ever.
:class:`IsolatedFmuComponent` keeps the modelDescription (and the variable map) in this
process and loads the FMU in a ``spawn``-ed worker; the two talk over a pipe in small tuples
of strings and floats (one round trip per step).

* When the worker dies (segfault, ``os._exit``, killed), the step raises
  :class:`~cosim.core.errors.SimulationFailed` ``"... worker died (signal 11, SIGSEGV)"`` and the
  master keeps every row recorded so far.
* With a ``timeout``, a request the worker has not answered within that many seconds kills
  the worker (SIGKILL) and fails the step: ``"doStep at t=500.0 took longer than the step
  timeout of 5 s (worker killed)"``.
* A signal that interrupts the parent while the worker is busy (Ctrl-C, SIGTERM) kills the
  worker at once in :meth:`IsolatedFmuComponent.terminate`: nothing waits for a hung FMU.
* The FMU is extracted into a ``cosim-fmu-*`` folder that this process creates and removes,
  so nothing is left behind however the worker ends. The worker also dies with its parent
  (``PR_SET_PDEATHSIG`` on Linux).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import shutil
import signal as _signal
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError, ParameterError, SimulationFailed
from cosim.core.fmu import FmuComponent
from cosim.core.varmap import MappedSignal, VarMap

__all__ = ["DEFAULT_STEP_TIMEOUT", "IsolatedFmuComponent"]

#: Step timeout [s] of an isolated plant when none is given (``cosim run --isolate``): far
#: above any healthy step of a process model, short enough that a hung FMU is noticed.
DEFAULT_STEP_TIMEOUT = 60.0
#: How long :meth:`IsolatedFmuComponent.terminate` waits for an idle worker to finish.
TERMINATE_WAIT = 5.0
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:  # pragma: no cover - runs in the child process
    """Ask Linux to kill this process when its parent dies (no orphaned, hung workers)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, _signal.SIGKILL, 0, 0, 0)


def _worker(conn: Any, path: str, name: str, interface: str,
            start_values: tuple[tuple[str, float], ...],
            mapping: tuple[tuple[str, str, str | None, float, float], ...],
            map_path: str, unpack_dir: str) -> None:  # pragma: no cover - child process
    """Serve one FMU: ``(op, *args)`` requests, ``("ok", result)`` or ``(kind, msg)`` replies."""
    _die_with_parent()
    # signals reach the whole process group: the parent handles them (and stops this worker)
    for sig in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
        _signal.signal(sig, _signal.SIG_IGN)
    varmap = VarMap(Path(map_path), {m[0]: MappedSignal(*m) for m in mapping})
    comp = FmuComponent(path, name=name, interface=interface,
                        start_values=dict(start_values), varmap=varmap, unpack_dir=unpack_dir)
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            break
        op = msg[0]
        try:
            if op == "setup":
                comp.setup(msg[1])
                result: Any = tuple(comp.get_outputs().items())
            elif op == "step":
                _, t, dt, inputs = msg
                if inputs:
                    comp.set_inputs(dict(inputs))
                comp.step(t, dt)
                result = tuple(comp.get_outputs().values())
            elif op == "set_parameter":
                comp.set_parameter(msg[1], msg[2])
                result = tuple(comp.get_outputs().values())
            elif op == "terminate":
                comp.terminate()
                conn.send(("ok", None))
                break
            else:
                raise CosimError(f"unknown request {op!r}")
            conn.send(("ok", result))
        except SimulationFailed as exc:
            conn.send(("failed", str(exc)))
        except CosimError as exc:
            conn.send(("error", str(exc)))
        except Exception as exc:
            conn.send(("failed", f"{type(exc).__name__}: {exc}"))
    conn.close()
    # skip interpreter teardown: FMU libraries stay loaded and some (embedded interpreters,
    # static destructors) do not survive it; nothing is left to flush
    os._exit(0)


class IsolatedFmuComponent(FmuComponent):
    """Same interface as :class:`FmuComponent`; the FMU runs in a child process.

    Parameters
    ----------
    *args, **kwargs
        As :class:`FmuComponent`.
    timeout : float, optional
        Wall-clock limit [s] of every request to the worker (initialisation, each
        ``doStep``, parameter changes); past it the worker is killed and the request fails.
        ``None``: wait for ever.
    """

    def __init__(self, *args: Any, timeout: float | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if timeout is not None and not (timeout > 0 and timeout < float("inf")):
            raise ParameterError("step_timeout", f" {timeout!r}: expected a positive number "
                                 "of seconds")
        self.timeout = timeout
        self._proc: Any = None
        self._conn: Any = None
        self._busy = False
        self._workdir: Path | None = None
        self._pending: dict[str, float] = {}
        self._outputs: dict[str, float] = {}

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Start the worker, which extracts, loads and initialises the FMU."""
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        mapping = tuple((m.signal, m.variable, m.unit, m.scale, m.offset)
                        for m in self.varmap.signals.values())
        self._workdir = Path(tempfile.mkdtemp(prefix="cosim-fmu-"))
        self._proc = ctx.Process(
            target=_worker, daemon=True,
            args=(child, str(self.path), self.name, self.interface,
                  tuple((k, float(v)) for k, v in self.start_values.items()), mapping,
                  str(self.varmap.path), str(self._workdir)))
        self._proc.start()
        child.close()
        self._conn = parent
        self._t = t0
        self._outputs = dict(self._call(("setup", float(t0)), f"initialisation at t={t0!r}"))

    def _call(self, msg: tuple, what: str) -> Any:
        conn = self._conn
        try:
            self._busy = True
            conn.send(msg)
            if self.timeout is not None and not conn.poll(self.timeout):
                self._kill()
                raise SimulationFailed(f"{self.path.name}: {what} took longer than the step "
                                       f"timeout of {self.timeout:g} s (worker killed)")
            kind, result = conn.recv()
            self._busy = False
        except (EOFError, BrokenPipeError, ConnectionResetError, OSError):
            why = self._death()
            raise SimulationFailed(f"{self.path.name}: {what} failed: {why}") from None
        if kind == "ok":
            return result
        if kind == "error":
            raise CosimError(result)
        raise SimulationFailed(result)

    def _death(self) -> str:
        """Why the worker is gone (after a broken pipe); cleans up."""
        proc = self._proc
        code = None
        if proc is not None:
            proc.join(timeout=TERMINATE_WAIT)
            code = proc.exitcode
        self._kill()
        if code is not None and code < 0:
            try:
                sig = _signal.Signals(-code).name
            except ValueError:
                sig = "unknown"
            return f"worker died (signal {-code}, {sig})"
        return f"worker died (exit code {code})"

    def _kill(self) -> None:
        """Kill the worker now and remove its folder (idempotent)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.close()
        proc, self._proc = self._proc, None
        if proc is not None:
            if proc.is_alive():
                proc.kill()
            proc.join()
        self._busy = False
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Inputs travel with the next step request."""
        self._pending.update(values)

    def set_parameter(self, name: str, value: float) -> None:
        """Change a tunable parameter in the worker (or a start value before setup)."""
        if self._conn is None:
            self.start_values[name] = value
            return
        vals = self._call(("set_parameter", name, float(value)), f"setting {name}")
        self._outputs = dict(zip(self._out_names, vals, strict=True))

    def step(self, t: float, dt: float) -> None:
        """One round trip: inputs, ``doStep``, outputs."""
        if self._conn is None:
            raise SimulationFailed(f"{self.path.name}: doStep at t={t!r} failed: no worker")
        inputs = tuple((k, float(v)) for k, v in self._pending.items())
        self._pending.clear()
        vals = self._call(("step", float(t), float(dt), inputs), f"doStep at t={t!r}")
        self._outputs = dict(zip(self._out_names, vals, strict=True))
        self._t = t + dt

    def get_outputs(self) -> dict[str, float]:
        """Outputs returned by the last request."""
        return dict(self._outputs)

    def terminate(self) -> None:
        """Stop the worker and remove its folder (idempotent).

        A worker still busy with a request (the parent was interrupted while waiting) is
        killed at once; an idle one is asked to terminate the FMU and given
        :data:`TERMINATE_WAIT` seconds.
        """
        conn = self._conn
        if conn is not None and not self._busy:
            try:
                conn.send(("terminate",))
                if conn.poll(TERMINATE_WAIT):
                    conn.recv()
            except (EOFError, OSError):
                pass
            proc = self._proc
            if proc is not None:
                proc.join(timeout=TERMINATE_WAIT)
        self._kill()
