"""``benchmarks/mixed_dead_times.py`` as a user runs it (its own process, a lag of two
samples): six closed loops, each printed with its IAE, ratio, fallbacks and violations; the
tracking law that knows both dead times has the least IAE."""

from __future__ import annotations

import re

from tests.benchmarks.running import bench


def test_the_benchmark_prints_each_controllers_iae() -> None:
    out = bench("mixed_dead_times.py", "--lag", "2", timeout=600)
    rows = re.findall(r"IAE\s+([\d.]+) m·s\s+\(([\d.]+)x\)\s+fallbacks\s+(\d+)\s+"
                      r"violations (\d+)\s+status ok", out)
    assert len(rows) == 6, out
    assert all(v == "0" for *_, v in rows)
    tracking = [float(ratio) for _, ratio, _, _ in rows[:3]]
    assert tracking[0] == 1.0 and min(tracking[1:]) > 1.0, out
