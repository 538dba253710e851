"""A real ``cosim serve-plant`` in its own process on 127.0.0.1, for the live-plant tests.

:func:`served` starts one on a free port, waits (bounded) until it listens, and stops it
(SIGTERM, then SIGKILL) however the test ends; nothing is mocked.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def env(**extra: str) -> dict[str, str]:
    """The environment of a ``cosim`` subprocess (the repository importable)."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra)


def cosim(*args: str) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", *args]


@dataclass
class Server:
    """A running ``cosim serve-plant``: its endpoint, process and stderr log."""

    endpoint: str
    port: int
    proc: subprocess.Popen
    log: Path

    def stop(self, timeout: float = 15.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout``; the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode

    def stderr(self) -> str:
        return self.log.read_text()


def start(tmp: Path, *args: str, port: int | None = None, extra_env: dict | None = None,
          name: str = "server") -> Server:
    """Start ``cosim serve-plant ARGS`` on ``port`` (a free one by default); wait until it
    listens (30 s at most)."""
    port = port or free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}"
    log = tmp / f"{name}.log"
    with log.open("w") as fh:
        proc = subprocess.Popen(cosim("serve-plant", "--endpoint", endpoint, *args),
                                env=env(**(extra_env or {})), cwd=tmp, stdout=fh, stderr=fh)
    server = Server(endpoint, port, proc, log)
    end = time.monotonic() + 30
    while True:
        if proc.poll() is not None:
            raise AssertionError(f"serve-plant exited {proc.returncode}: {server.stderr()}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            return server
        if time.monotonic() > end:
            server.stop()
            raise AssertionError(f"serve-plant did not listen within 30 s: {server.stderr()}")
        time.sleep(0.1)


@contextlib.contextmanager
def served(tmp: Path, *args: str, **kw: object) -> Iterator[Server]:
    """:func:`start` for the ``with`` block; stopped after it, however it ends."""
    server = start(tmp, *args, **kw)  # type: ignore[arg-type]
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def short_scenario(tmp_path: Path) -> Path:
    """The paper's first set-point steps, shortened: 60 samples of 25 s."""
    path = tmp_path / "short.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n1000,,1.0\n1500,,\n")
    return path


@pytest.fixture
def safe_problem(tmp_path: Path) -> Path:
    """The four-tank's problem with safe inputs (qa = 0, qb held)."""
    from cosim_adapters.problems import default_problem_path

    text = default_problem_path().read_text()
    text = text.replace('description = "pump a flow"', 'description = "pump a flow"\nsafe = 0.0')
    path = tmp_path / "problem_safe.toml"
    path.write_text(text)
    return path
