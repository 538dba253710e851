"""Routing the log messages of running FMUs to the component that owns each instance.

fmpy formats FMI 2 variadic log messages in a small native proxy that keeps ONE Python
logger per process, so messages are routed here by instance name: an
:class:`~cosim.core.fmu.FmuComponent` registers a sink (a bounded deque) under its instance name
with :func:`attach`, and its warnings and errors land there to explain a failure. A message
from an instance without a sink is printed.

Thread-safe: instance names are unique in the process, a sink is set and removed in one
dictionary operation, and the process-wide callbacks are built once under a lock (a campaign
worker runs two FMUs at once from two threads).
"""

from __future__ import annotations

import ctypes
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["STATUS_LABELS", "attach", "detach", "fmi2_callbacks", "fmi3_logger", "route"]

#: FMI status names by value (FMI 2 and 3 number them alike).
STATUS_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")

_SINKS: dict[str, deque[str]] = {}
_FMI2_CALLBACKS: Any = None
#: The native proxy keeps bare pointers to these: they live as long as the process.
_CALLBACK_REFS: list[Any] = []
_CALLBACKS_LOCK = threading.Lock()


def attach(instance: str, sink: deque[str]) -> None:
    """Send the warnings and errors of FMU instance ``instance`` to ``sink``."""
    _SINKS[instance] = sink


def detach(instance: str) -> None:
    """Stop routing ``instance``'s messages (later ones are printed)."""
    _SINKS.pop(instance, None)


def route(instance: bytes | None, status: int, category: bytes | None,
          message: bytes | None) -> None:
    """Deliver one log message: to its instance's sink (warnings and worse), else print it."""
    name = (instance or b"").decode("utf-8", "replace")
    text = " ".join((message or b"").decode("utf-8", "replace").split())
    label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
    sink = _SINKS.get(name)
    if sink is None:
        print(f"[{label}] {name}: {text}")
    elif status >= 1:  # keep warnings and errors: they explain failures
        sink.append(f"[{label}] {text}")


def fmi2_callbacks() -> Any:
    """The process-wide ``fmi2CallbackFunctions`` whose logger calls :func:`route` (built
    once, by whichever thread asks first)."""
    global _FMI2_CALLBACKS
    with _CALLBACKS_LOCK:
        if _FMI2_CALLBACKS is None:
            _FMI2_CALLBACKS = _make_fmi2_callbacks()
    return _FMI2_CALLBACKS


def _make_fmi2_callbacks() -> Any:
    from fmpy import fmi2

    def logger(env, instance, status, category, message):
        route(instance, status, category, message)

    cb = fmi2.fmi2CallbackFunctions()
    # the native proxy keeps a bare pointer to the Python logger: hold every callback
    # object for the life of the process
    _CALLBACK_REFS.extend([fmi2.fmi2CallbackLoggerTYPE(logger),
                           fmi2.fmi2CallbackAllocateMemoryTYPE(fmi2.calloc),
                           fmi2.fmi2CallbackFreeMemoryTYPE(fmi2.free), logger])
    cb.logger, cb.allocateMemory, cb.freeMemory = _CALLBACK_REFS[:3]
    try:
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(ctypes.byref(cb))
    except Exception:  # pragma: no cover - proxy missing on this platform
        pass
    return cb


def fmi3_logger(instance: str) -> Callable[[Any, int, bytes | None, bytes | None], None]:
    """An FMI 3 ``logMessage`` callback that routes ``instance``'s messages."""
    name = instance.encode()

    def log3(env, status, category, message):
        route(name, status, category, message)

    return log3
