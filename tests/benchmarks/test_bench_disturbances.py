"""``benchmarks/bench_disturbances.py`` as a user runs it (its own process, one small round):
both closed loops run, on the compiled kernel, and the ratios are printed."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_benchmark_times_both_controllers() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_disturbances.py"),
                           "--rounds", "1", "--n", "8"], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r"median\s+([\d.]+) ms\s+p99\s+([\d.]+) ms", proc.stdout)
    assert len(rows) == 2 and all(float(a) > 0 and float(b) >= float(a) for a, b in rows)
    assert re.search(r"ratio \(aim <= 1.2x\)\s+median\s+[\d.]+x\s+p99\s+[\d.]+x", proc.stdout)
