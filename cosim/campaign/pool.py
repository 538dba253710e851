"""Controllers of a campaign worker: built once per configuration, used by one run at a time.

A Dask worker may run several runs at once (``dask worker --nthreads 2``; Dask's default is
one thread per core). A controller holds the state of the run it serves (the observer's
estimate, the reference, the solver's warm start and workspaces), so two runs must never
share an instance. :class:`ControllerPool` keeps the idle instances per configuration
(controller name and options): a run *takes* one (building it when none is idle) and gives it
back when it ended ``ok``; an instance from a run that failed or raised is dropped, so that
no half-updated controller serves another run. A controller's ``setup()`` restarts it
exactly (the robust MPC rebuilds its solver), so a run gives the same numbers with a new
instance or with one that served a thousand runs before.

The pool holds at most ``size`` idle instances in all (the least recently returned go
first); the instances in use are not counted (one per running run, as many as the worker's
threads).
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["POOL_SIZE", "ControllerPool", "controller_key"]

#: Idle controllers kept per worker process, over every configuration.
POOL_SIZE = 8


def controller_key(name: str, options: Mapping[str, Any]) -> str:
    """The configuration key of a controller: its name and options, as canonical JSON."""
    return json.dumps([name, dict(options)], sort_keys=True, default=str)


class ControllerPool:
    """Idle controllers per configuration, each handed to one run at a time.

    Parameters
    ----------
    size : int
        Most idle instances kept, over every configuration.
    factory : callable, optional
        ``factory(name, options)`` builds a controller (default
        :func:`cosim.core.registry.create`).
    """

    def __init__(self, size: int = POOL_SIZE,
                 factory: Callable[[str, dict[str, Any]], Any] | None = None) -> None:
        if size < 0:
            raise ValueError(f"pool size {size!r}: expected a non-negative integer")
        self.size = int(size)
        self._factory = factory
        self._idle: OrderedDict[str, list[Any]] = OrderedDict()
        self._lock = threading.Lock()
        #: Controllers built by this pool (a measure of reuse).
        self.built = 0

    def take(self, name: str, options: Mapping[str, Any]) -> tuple[str, Any]:
        """An idle controller of this configuration, or a new one; ``(key, controller)``.

        The caller owns the controller until it gives it back (:meth:`give_back`) or drops
        it (does nothing). Building it may raise (a bad option: a
        :class:`~cosim.core.errors.CosimError`).
        """
        key = controller_key(name, options)
        with self._lock:
            idle = self._idle.get(key)
            if idle:
                ctrl = idle.pop()
                if not idle:
                    del self._idle[key]
                return key, ctrl
        factory = self._factory
        if factory is None:
            from cosim.core import registry

            factory = registry.create
        ctrl = factory(name, dict(options))   # outside the lock: building takes seconds
        with self._lock:
            self.built += 1
        return key, ctrl

    def give_back(self, key: str, ctrl: Any) -> None:
        """Return a controller whose run ended normally; the oldest idle ones beyond
        :attr:`size` are dropped."""
        with self._lock:
            self._idle.setdefault(key, []).append(ctrl)
            self._idle.move_to_end(key)
            while self.idle() > self.size:
                oldest = next(iter(self._idle))
                self._idle[oldest].pop(0)
                if not self._idle[oldest]:
                    del self._idle[oldest]

    def idle(self, key: str | None = None) -> int:
        """Idle instances (of one configuration key, or in all)."""
        if key is not None:
            return len(self._idle.get(key, ()))
        return sum(len(v) for v in self._idle.values())

    def clear(self) -> None:
        """Drop every idle controller."""
        with self._lock:
            self._idle.clear()
