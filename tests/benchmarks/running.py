"""A benchmark run as a user runs it, for the benchmarks' tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def bench(script: str, *args: str, timeout: float = 900) -> str:
    """``python benchmarks/<script> <args>`` in its own process: what it printed, once it
    exited 0 (else the test fails with its output)."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args],
                          capture_output=True, text=True, timeout=timeout, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout
