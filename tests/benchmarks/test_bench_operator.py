"""``benchmarks/bench_operator.py`` as a user runs it (its own process, a short run): both
loops timed, their statistics and the ratio of their 99th percentiles printed (the target,
issue 61: at most 2; a benchmark's number, not asserted here)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_benchmark_times_the_step_with_and_without_operator_changes() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_operator.py"),
                           "--steps", "40"], capture_output=True, text=True, timeout=900,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r"(baseline|changes) +median ([\d.]+) p90 ([\d.]+) p99 ([\d.]+) max "
                      r"([\d.]+) ms over 40 steps", proc.stdout)
    assert [r[0] for r in rows] == ["baseline", "changes"], proc.stdout
    assert all(0 < float(r[1]) <= float(r[2]) <= float(r[3]) <= float(r[4]) for r in rows)
    assert re.search(r"ratio p99 [\d.]+x \(target <= 2\)", proc.stdout)
