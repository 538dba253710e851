"""A ``cosim serve-plant`` in a process of its own, started and stopped from Python: the
rehearsal's virtual plant for scripts, benchmarks and tests.

:func:`start_served_plant` starts one on a free port of 127.0.0.1 (or the port given), waits
until it listens (bounded) and returns a :class:`ServedPlant` whose :meth:`~ServedPlant.stop`
sends SIGTERM, then SIGKILL; :func:`served_plant` does the same for a ``with`` block, the
server stopped however the block ends.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from cosim.core.errors import CosimError

__all__ = ["ServedPlant", "free_port", "served_plant", "start_served_plant"]


def free_port() -> int:
    """A TCP port of 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class ServedPlant:
    """A running ``cosim serve-plant``: its endpoint and port, its process, its log (its
    standard output and error)."""

    endpoint: str
    port: int
    proc: subprocess.Popen
    log: Path

    def stop(self, timeout: float = 15.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout`` seconds; the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode

    def stderr(self) -> str:
        """What the server printed."""
        return self.log.read_text()


def start_served_plant(*args: str, log: str | Path, port: int | None = None,
                       env: Mapping[str, str] | None = None,
                       wait: float = 30.0) -> ServedPlant:
    """``cosim serve-plant ARGS --endpoint opc.tcp://127.0.0.1:PORT`` (a free port unless
    given), its output into ``log``; returns once it listens.

    Raises
    ------
    CosimError
        It exited, or did not listen within ``wait`` seconds (then it is stopped); the
        message ends with its last line.
    """
    port = port or free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}"
    log = Path(log)
    with log.open("w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "serve-plant", "--endpoint",
                                 endpoint, *args], env=dict(env or os.environ),
                                stdout=fh, stderr=fh)
    served = ServedPlant(endpoint, port, proc, log)
    end = time.monotonic() + wait
    while True:
        if proc.poll() is not None:
            raise CosimError(f"cosim serve-plant exited {proc.returncode}: "
                             f"{_last_line(served)}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            return served
        if time.monotonic() > end:
            served.stop()
            raise CosimError(f"cosim serve-plant did not listen within {wait:g} s: "
                             f"{_last_line(served)}")
        time.sleep(0.1)


@contextlib.contextmanager
def served_plant(*args: str, log: str | Path, **options: object) -> Iterator[ServedPlant]:
    """:func:`start_served_plant` for a ``with`` block; stopped after it, however it ends."""
    served = start_served_plant(*args, log=log, **options)  # type: ignore[arg-type]
    try:
        yield served
    finally:
        served.stop()


def _last_line(served: ServedPlant) -> str:
    lines = served.stderr().strip().splitlines()
    return lines[-1] if lines else "(nothing printed)"
