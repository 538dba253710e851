"""``benchmarks/bench_controller_fmu.py`` run as a user runs it (its own process), on a short
scenario: it prints the steps' times (the Python step, the FMU in this process and in a
worker), the FMU's ratios, and inputs equal to the bit."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("options", [[], ["--option", 'law="paper"', "--option",
                                           "governor=false"], ["--option", 'law="paper"']],
                         ids=["tracking", "paper", "paper-governor"])
def test_the_benchmark_prints_ratios_and_equal_inputs(options: list[str], tmp_path: Path
                                                      ) -> None:
    scenario = tmp_path / "short.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n250,1.3,1.4\n1000,,\n")
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_controller_fmu.py"),
                           "--repeats", "1", "--fmi", "2", "--scenario", str(scenario),
                           *options], capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "41 controller steps x 1 repeats, FMI 2.0, options " in proc.stdout
    assert ("'law': 'paper'" in proc.stdout) is bool(options)
    for name in ("fmu", "worker"):
        assert re.search(name + r": median [0-9.]+ ms, p99 [0-9.]+ ms  \([0-9.]+x, [0-9.]+x "
                         r"the Python step\)", proc.stdout), proc.stdout
    assert re.search(r"the worker process adds -?[0-9]+ us per step", proc.stdout)
    assert "largest input difference: 0\n" in proc.stdout
