"""``benchmarks/mixed_dead_times.py`` as a user runs it (its own process, a lag of two
samples): six closed loops, each printed with its IAE, ratio, fallbacks and violations; the
tracking law that knows both dead times has the least IAE."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_benchmark_prints_each_controllers_iae() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "mixed_dead_times.py"),
                           "--lag", "2"], capture_output=True, text=True, timeout=600,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r"IAE\s+([\d.]+) m·s\s+\(([\d.]+)x\)\s+fallbacks\s+(\d+)\s+"
                      r"violations (\d+)\s+status ok", proc.stdout)
    assert len(rows) == 6, proc.stdout
    assert all(v == "0" for *_, v in rows)
    tracking = [float(ratio) for _, ratio, _, _ in rows[:3]]
    assert tracking[0] == 1.0 and min(tracking[1:]) > 1.0, proc.stdout
