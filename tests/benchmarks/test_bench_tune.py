"""``benchmarks/bench_tune.py`` as a user runs it (its own process, the shipped model only, the
runs with the gains off left out to keep it short: ``--gain-uncertainty 0``): tune's time in
one process and in workers, their ratio and the same choice are printed."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_benchmark_times_tune_both_ways() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_tune.py"),
                           "--plants", "fourtank", "--gain-uncertainty", "0"],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    row = re.search(r"^fourtank\s+2 x 2\s+([\d.]+) s\s+([\d.]+) s\s+([\d.]+) s\s+"
                    r"([\d.]+)x\s+yes", proc.stdout, re.M)
    assert row and all(float(v) > 0 for v in row.groups()), proc.stdout
    assert re.search(r"slowest tune with workers: [\d.]+ s", proc.stdout)
