"""A controller against a live process over OPC UA (IEC 62541), on the wall clock.

A plant is reached through its control system, and control systems speak OPC UA. This package
is the co-simulation's counterpart for that: :mod:`cosim.live.server` serves a plant FMU as an
OPC UA server stepped on the wall clock (the virtual plant of ``cosim serve-plant``, to
rehearse on), :mod:`cosim.live.session` is the client that reads a plant's measurements and
writes its inputs (``cosim run --plant opc.tcp://...``), :mod:`cosim.live.clock` the real-time
loop that drives any controller through it and answers every fault a live process has
(stale values, lost links, overrunning steps, signals), :mod:`cosim.live.tags` maps the
problem's signals onto a real plant's tags, and :mod:`cosim.live.security` holds the
certificates, trust list and user of a secured connection.

asyncua (pure Python) is imported only when a live command runs.
"""

from __future__ import annotations

import logging

#: The loggers of asyncua (and of its certificate checks) and asyncio: a live command speaks
#: in its own one-line messages, never in a library's log records or tracebacks.
LIBRARY_LOGGERS = ("asyncua", "asyncuagds", "asyncio")


def quiet_libraries() -> None:
    """Silence :data:`LIBRARY_LOGGERS` (a live command reports what matters itself)."""
    for name in LIBRARY_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)
