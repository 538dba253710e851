"""``benchmarks/bench_operator.py`` as a user runs it (its own process, a short run): both
loops timed, their statistics and the ratio of their 99th percentiles printed (the target,
issue 61: at most 2; a benchmark's number, not asserted here)."""

from __future__ import annotations

import re

import pytest

from tests.benchmarks.running import bench


@pytest.mark.slow
def test_the_benchmark_times_the_step_with_and_without_operator_changes() -> None:
    out = bench("bench_operator.py", "--steps", "40")
    rows = re.findall(r"(baseline|changes) +median ([\d.]+) p90 ([\d.]+) p99 ([\d.]+) max "
                      r"([\d.]+) ms over 40 steps", out)
    assert [r[0] for r in rows] == ["baseline", "changes"], out
    assert all(0 < float(r[1]) <= float(r[2]) <= float(r[3]) <= float(r[4]) for r in rows)
    assert re.search(r"ratio p99 [\d.]+x \(target <= 2\)", out)
