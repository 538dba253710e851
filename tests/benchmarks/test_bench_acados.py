"""``benchmarks/bench_acados.py`` as a user runs it (its own process; ``make acados`` made the
acados venv, as ``make test`` does): the paper's FHOCP built in acados, solved on the first
captured problems by its SQP and SQP-RTI beside the kernel, every answer judged by numpy."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ACADOS_PYTHON = ROOT / ".venv-acados" / "bin" / "python"


@pytest.mark.slow
@pytest.mark.skipif(not ACADOS_PYTHON.is_file(), reason="no acados venv: make acados")
def test_acados_solves_the_same_problems_as_the_kernel() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_acados.py"),
                           "--repeats", "1", "--problems", "40", "--variants",
                           "sqp-exact,sqp-rti"], capture_output=True, text=True, timeout=900,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "on the 40 problems of the paper scenario's closed loop" in proc.stdout
    rows = {m[0]: m for m in re.findall(
        r"^(kernel|sqp-exact|sqp-rti) +([\d.]+) +([\d.]+) +([\d.]+) +(\d+) / *(\d+) +(\d+) +"
        r"([+-][\d.]+e[+-]\d+) +(\d+) +(\d+) +(\d+)$", proc.stdout, re.M)}
    assert set(rows) == {"kernel", "sqp-exact", "sqp-rti"}, proc.stdout
    for row in rows.values():
        assert 0 < float(row[1]) <= float(row[2]) <= float(row[3]), row
    # the first problems are near a steady state: every solver converges there, to the
    # kernel's answer, within the constraints
    failed, rel, violating = 6, 7, 10
    assert rows["kernel"][failed] == "0" and rows["kernel"][violating] == "0"
    assert rows["sqp-exact"][failed] == "0" and abs(float(rows["sqp-exact"][rel])) < 1e-6
    assert rows["sqp-exact"][violating] == "0"
