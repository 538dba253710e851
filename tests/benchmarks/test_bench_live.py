"""``benchmarks/bench_live.py`` as a user runs it (its own process, two short runs): the loop
latency, its ratio to the controller step, and the largest speed-up without a deadline miss
are printed."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_benchmark_prints_latencies_and_the_largest_speed() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_live.py"),
                           "--samples", "20", "--speed", "250", "--max-speed", "500"],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r"^\s+(\d+)\s+[\d.]+ms\s+([\d.]+)ms\s+([\d.]+)ms\s+([\d.]+)ms\s+"
                      r"([\d.]+)ms\s+([\d.]+)x\s+(\d+)\s+(\d+)$", proc.stdout, re.M)
    assert [r[0] for r in rows][:1] == ["250"] and len(rows) >= 1
    for _, loop_med, loop_p99, step_med, _, ratio, _, _ in rows:
        assert float(loop_p99) >= float(loop_med) > float(step_med) > 0 and float(ratio) > 1
    assert re.search(r"largest speed-up with 0 deadline misses(: none| \(and every smaller one "
                     r"tried\): K = \d+)", proc.stdout)
