"""``benchmarks/study_capped_solves.py --paths`` as a user runs it (its own process): the
study's items are printed, and its item 6 finds what the design record states: solved to
convergence from the same guesses, the paper law's FHOCPs reach other KKT points under
another line search, and the closed loop's answers move beyond the regression references'
1e-4 (the SQP's path picks the local optimum)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_another_path_reaches_other_optima() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "study_capped_solves.py"),
                           "--paths"], capture_output=True, text=True, timeout=600,
                          check=False, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for item in "12346":
        assert re.search(rf"^{item}\. ", proc.stdout, re.M), proc.stdout
    apart = re.search(r"6\. the same (\d+) FHOCPs from the same guesses, to convergence with "
                      r"the default line search and with max_iter_ls=10, beta=0.5: (\d+) "
                      r"converge to first inputs more than 0.001 apart", proc.stdout)
    assert apart, proc.stdout
    assert int(apart[1]) > 1000 and int(apart[2]) >= 1, proc.stdout
    loop = re.search(r"6\. the closed loop with .*differ from the default's by up to "
                     r"([\d.]+) of their range, first beyond 1e-4 at step (\d+)", proc.stdout)
    assert loop and float(loop[1]) > 1e-4, proc.stdout
