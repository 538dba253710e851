"""An :class:`~cosim.fmu.FmuComponent` whose native code runs in a worker process.

An FMU is native code: a segmentation fault inside ``doStep`` would take the whole runner
down with it, results and all. :class:`IsolatedFmuComponent` keeps the modelDescription (and
the variable map) in this process and loads the FMU in a ``spawn``-ed worker; the two talk
over a pipe in small tuples of strings and floats (one round trip per step). When the worker
dies, the step raises :class:`~cosim.errors.SimulationFailed` ``"... worker died (signal 11)"``
and the master keeps every row recorded so far.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal as _signal
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cosim.errors import CosimError, SimulationFailed
from cosim.fmu import FmuComponent
from cosim.varmap import MappedSignal, VarMap


def _worker(conn: Any, path: str, name: str, interface: str,
            start_values: tuple[tuple[str, float], ...],
            mapping: tuple[tuple[str, str, str | None, float, float], ...],
            map_path: str) -> None:  # pragma: no cover - runs in the child process
    """Serve one FMU: ``(op, *args)`` requests, ``("ok", result)`` or ``(kind, msg)`` replies."""
    # Ctrl-C reaches the whole process group: the parent handles it (and stops this worker)
    _signal.signal(_signal.SIGINT, _signal.SIG_IGN)
    varmap = VarMap(Path(map_path), {m[0]: MappedSignal(*m) for m in mapping})
    comp = FmuComponent(path, name=name, interface=interface,
                        start_values=dict(start_values), varmap=varmap)
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
    """Same interface as :class:`FmuComponent`; the FMU runs in a child process."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._proc: Any = None
        self._conn: Any = None
        self._pending: dict[str, float] = {}
        self._outputs: dict[str, float] = {}

    def setup(self, t0: float, stop_time: float | None = None) -> None:
        """Start the worker, which extracts, loads and initialises the FMU."""
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        mapping = tuple((m.signal, m.variable, m.unit, m.scale, m.offset)
                        for m in self.varmap.signals.values())
        self._proc = ctx.Process(
            target=_worker, daemon=True,
            args=(child, str(self.path), self.name, self.interface,
                  tuple((k, float(v)) for k, v in self.start_values.items()), mapping,
                  str(self.varmap.path)))
        self._proc.start()
        child.close()
        self._conn = parent
        self._t = t0
        self._outputs = dict(self._call(("setup", float(t0)), f"initialisation at t={t0!r}"))

    def _call(self, msg: tuple, what: str) -> Any:
        try:
            self._conn.send(msg)
            kind, result = self._conn.recv()
        except (EOFError, BrokenPipeError, ConnectionResetError, OSError):
            self._proc.join(timeout=5)
            code = self._proc.exitcode
            if code is not None and code < 0:
                try:
                    sig = _signal.Signals(-code).name
                except ValueError:
                    sig = "unknown"
                why = f"worker died (signal {-code}, {sig})"
            else:
                why = f"worker died (exit code {code})"
            self._conn = None
            raise SimulationFailed(f"{self.path.name}: {what} failed: {why}") from None
        if kind == "ok":
            return result
        if kind == "error":
            raise CosimError(result)
        raise SimulationFailed(result)

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
        """Stop the worker (idempotent)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.send(("terminate",))
                conn.recv()
            except (EOFError, OSError):
                pass
            conn.close()
        if self._proc is not None:
            self._proc.join(timeout=10)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
            self._proc = None
