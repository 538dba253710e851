"""``benchmarks/disturbance_campaign.py`` as a user runs it (its own process), small: both
campaigns run on the heater with a dead time, the table is printed, and the IAE oracle runs on
every run (its model the plant's own: the benchmark stops otherwise); both campaigns on the
furnace with a measured load."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_campaigns_compare_the_mpc_with_both_pis() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "disturbance_campaign.py"),
                           "--runs", "2", "--steps", "2000", "--epochs", "20", "--oracle"],
                          capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ratios = re.findall(r"MPC summed IAE / PI ([\d.]+), / PI with feedforward ([\d.]+)",
                        proc.stdout)
    assert len(ratios) == 2 and all(float(a) > 0 and float(b) > 0 for a, b in ratios)
    rows = re.findall(r"(mpc|pi-ff|pi) +overshoot median +([\d.]+) %, largest +([\d.]+) %; "
                      r"violating runs (\d+)", proc.stdout)
    assert sorted(r[0] for r in rows) == ["mpc", "mpc", "pi", "pi", "pi-ff", "pi-ff"]
    oracle = re.findall(r"oracle / PI ([\d.]+) \(the causal bound\), / PI with feedforward "
                        r"([\d.]+); MPC / oracle ([\d.]+)", proc.stdout)
    assert len(oracle) == 2, proc.stdout
    # no causal controller beats the oracle by more than its horizon and local optima allow
    assert all(0 < float(o) < 1.0 and float(m) > 0.95 for o, _, m in oracle), oracle


def test_the_furnace_with_a_measured_load_runs_both_campaigns() -> None:
    """The 2 x 2 furnace with its throughput measured: both campaigns, each output's
    overshoot, no oracle (``tests/benchmarks/test_oracle_bound.py`` checks its equations)."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "disturbance_campaign.py"),
                           "--plant", "furnace_load", "--runs", "2", "--steps", "1500",
                           "--epochs", "10"],
                          capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "two-zone furnace, product throughput measured: 2 runs" in proc.stdout
    names = re.findall(r"^  (\S+) +MPC summed IAE / PI [\d.]+", proc.stdout, re.M)
    assert names == ["setpoints", "load"], proc.stdout
    rows = re.findall(r"(mpc|pi-ff|pi) +overshoot median +([\d.]+) %", proc.stdout)
    assert len(rows) == 6 and all(float(o) > 0 for _, o in rows)
