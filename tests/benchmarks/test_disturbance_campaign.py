"""``benchmarks/disturbance_campaign.py`` as a user runs it (its own process), small: both
campaigns run on the heater with a dead time, and the table is printed."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_campaigns_compare_the_mpc_with_both_pis() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "disturbance_campaign.py"),
                           "--runs", "2", "--steps", "2000", "--epochs", "20"],
                          capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ratios = re.findall(r"MPC summed IAE / PI ([\d.]+), / PI with feedforward ([\d.]+)",
                        proc.stdout)
    assert len(ratios) == 2 and all(float(a) > 0 and float(b) > 0 for a, b in ratios)
    rows = re.findall(r"(mpc|pi-ff|pi) +overshoot median +([\d.]+) %, largest +([\d.]+) %; "
                      r"violating runs (\d+)", proc.stdout)
    assert sorted(r[0] for r in rows) == ["mpc", "mpc", "pi", "pi", "pi-ff", "pi-ff"]
