"""``benchmarks/bench_opcua_client.py`` as a user runs it (its own process, a short run against
``cosim serve-plant``): each client's read and write latencies and its speed-up over the
session of ``cosim run`` are printed, after every client's answers agreed and its writes
were read back."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CLIENTS = ("session", "asyncua-prebuilt", "asyncua-inline")


@pytest.mark.slow
def test_the_benchmark_prints_each_clients_latency_and_speed_up() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_opcua_client.py"),
                           "--samples", "40", "--period", "0.01", "--servers", "serve-plant",
                           "--clients", ",".join(CLIENTS)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "every write read back" in proc.stdout
    agreed = re.search(r"answers agreed in (\d+) of 40 rounds", proc.stdout)
    assert agreed and int(agreed.group(1)) >= 38, proc.stdout
    number = r"\s+([\d.]+)ms\s+([\d.]+)ms"
    rows = re.findall(rf"^\s+(\S+){number}{number}{number}\s+([\d.]+)x\s+([\d.]+)x\s+"
                      r"([\d.]+)ms$", proc.stdout, re.M)
    assert [r[0] for r in rows] == list(CLIENTS), proc.stdout
    for _, rm, rp, wm, wp, bm, bp, speed_med, speed_p99, cpu in rows:
        assert float(rp) >= float(rm) > 0 and float(wp) >= float(wm) > 0
        assert float(bp) >= float(bm) > 0 and float(speed_med) > 0 and float(speed_p99) > 0
        assert float(cpu) > 0
    assert rows[0][7:9] == ("1.00", "1.00")            # the session against itself
