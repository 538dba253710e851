"""What the live commands run: :func:`serve` (``cosim serve-plant``, through
:func:`cosim.api.serve_plant`), and the options of ``cosim run --plant opc.tcp://...``
(:class:`LiveOptions`; the plant is opened by :func:`cosim.live.plant.open_live`).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError, SimulationFailed
from cosim.live.security import Security
from cosim.live.server import DEFAULT_ENDPOINT

__all__ = ["LiveOptions", "ServeSummary", "check_endpoint", "serve"]


class ServeSummary(dict):
    """What a served plant did: ``samples``, ``overruns``, ``clipped``, ``stopped_by``."""


def serve(component: Any, bound: Any, *, endpoint: str = DEFAULT_ENDPOINT,
          speed: float = 1.0, security: Security | None = None, frozen: bool = False,
          record: str | Path | None = None, duration: float | None = None,
          on_notice: Callable[[str], None] = print) -> ServeSummary:
    """Serve the plant ``component`` (bound to the problem ``bound``) as an OPC UA server on
    the wall clock until a signal (SIGINT, SIGTERM, SIGHUP) or ``duration`` seconds: what
    :func:`cosim.api.serve_plant` (the twin of ``cosim serve-plant``) runs; the server is
    :class:`cosim.live.server.VirtualPlant`.

    Parameters
    ----------
    component : Component
        The plant, not yet set up.
    bound : ControlProblem
        The problem it is served by.
    endpoint : str
        ``opc.tcp://host:port`` to listen on.
    speed : float
        Speed-up K: one sample every ``Ts / K`` seconds.
    security : Security, optional
        Default: no security.
    frozen : bool
        Hold the initial state until a client writes an input.
    record : path, optional
        CSV of the plant's trajectory (one row per sample).
    duration : float, optional
        Stop after this many seconds [wall clock].

    Raises
    ------
    CosimError
        Bad speed, duration or endpoint, or the endpoint cannot be listened on.
    SimulationFailed
        The plant failed while served.
    """
    from cosim.live.server import VirtualPlant

    if not (speed > 0 and math.isfinite(speed)):
        raise CosimError(f"--speed {speed!r}: must be a positive number (the speed-up K)")
    if duration is not None and not duration > 0:
        raise CosimError(f"--duration {duration!r}: must be a positive number of seconds")
    check_endpoint(endpoint, "--endpoint")
    server = VirtualPlant(component, bound, endpoint=endpoint, speed=speed,
                          security=security, frozen=frozen, record=record, notice=on_notice)
    stopped = {"by": "duration" if duration is not None else ""}

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            loop.add_signal_handler(sig, _stopper(stop, stopped, sig))
        try:
            await server.serve(stop, duration)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                loop.remove_signal_handler(sig)

    try:
        asyncio.run(main())
    except OSError as exc:
        raise CosimError(f"--endpoint {endpoint}: cannot listen: {exc.strerror or exc}") \
            from None
    except (CosimError, SimulationFailed):
        raise
    except Exception as exc:   # the plant FMU failed, or asyncua did
        what = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise SimulationFailed(f"the virtual plant stopped at t = {server.t:g} s after "
                               f"{server.samples} samples: {what}") from exc
    return ServeSummary(samples=server.samples, overruns=server.overruns,
                        clipped=server.clipped, stopped_by=stopped["by"])


def _stopper(stop: asyncio.Event, stopped: dict, sig: int) -> Callable[[], None]:
    def handler() -> None:
        stopped["by"] = signal.Signals(sig).name
        stop.set()
    return handler


def check_endpoint(endpoint: str, flag: str) -> None:
    """``opc.tcp://host:port[/path]``, else a one-line error naming ``flag``."""
    from urllib.parse import urlparse

    url = urlparse(endpoint)
    port = None
    with contextlib.suppress(ValueError):
        port = url.port
    if url.scheme != "opc.tcp" or not url.hostname or port is None:
        raise CosimError(f"{flag} {endpoint}: expected opc.tcp://HOST:PORT (e.g. "
                         f"{DEFAULT_ENDPOINT})")


@dataclass(frozen=True)
class LiveOptions:
    """How ``cosim run --plant opc.tcp://...`` meets the plant.

    Attributes
    ----------
    tags : path, optional
        A tags file (:mod:`cosim.live.tags`); default: the signals by name in the folder
        named for the problem (``cosim serve-plant``'s layout).
    speed : float
        The plant's speed-up K (1 for a real plant): one sample every ``Ts / K`` seconds.
    watchdog : int, optional
        Stale samples in a row before the safe inputs are written.
    security : Security
        Default: no security (the command asks for it explicitly).
    heartbeat : str, optional
        A node (node id or browse path, as in a tags file) written with a counter every
        sample, so that the control system sheds the controller when it stops.
    min_controlled : float
        The least share of its samples at which a run must have written inputs its
        controller computed from fresh data; a run below it, or that never wrote an input,
        did not control the plant and ends with exit 1 (:class:`cosim.live.clock.WallClock`).
    """

    tags: str | Path | None = None
    speed: float = 1.0
    watchdog: int | None = None
    security: Security = field(default_factory=Security)
    heartbeat: str | None = None
    min_controlled: float = 0.5

    def check(self) -> None:
        """Refuse options out of their range (one line naming the option).

        Raises
        ------
        CosimError
        """
        if not (self.speed > 0 and math.isfinite(self.speed)):
            raise CosimError(f"--speed {self.speed!r}: must be a positive number (the "
                             "plant's speed-up K)")
        if self.watchdog is not None and self.watchdog < 1:
            raise CosimError(f"--watchdog {self.watchdog!r}: must be a whole number of "
                             "samples >= 1")
        if not 0.0 <= self.min_controlled <= 1.0:
            raise CosimError(f"--min-controlled {self.min_controlled!r}: must be a share "
                             "from 0 to 1 of the run's samples")
