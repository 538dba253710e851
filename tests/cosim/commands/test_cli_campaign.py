"""``cosim campaign`` end to end: a scheduler that cannot be reached is bad input (exit 2, one
line naming the address, nothing written)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
SPEC = """\
[campaign]
runs = 2
scenario = "short.csv"
controller = "pi"

[draw]
"sensor.h1.bias" = { uniform = [-0.01, 0.01] }
"""


def campaign(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    (tmp_path / "short.csv").write_text("time,ref.h1,ref.h2\n0,0.6,0.6\n500,,\n")
    (tmp_path / "spec.toml").write_text(SPEC)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "cosim.cli", "campaign", "spec.toml", "--out",
                           "out", *args], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)


def closed_port() -> int:
    """A port on 127.0.0.1 nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_an_unreachable_scheduler_is_one_line_exit_2(tmp_path: Path) -> None:
    address = f"tcp://127.0.0.1:{closed_port()}"
    proc = campaign(tmp_path, "--scheduler", address)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"cosim campaign: error: --scheduler {address}: cannot connect:")
    assert address in lines[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists()   # nothing was run, nothing written


def test_a_malformed_scheduler_address_is_one_line_exit_2(tmp_path: Path) -> None:
    proc = campaign(tmp_path, "--scheduler", "nonsense://127.0.0.1:1")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "cosim campaign: error: --scheduler nonsense://127.0.0.1:1: cannot connect: unknown "
        "address scheme 'nonsense'"), proc.stderr
    assert not (tmp_path / "out").exists()
