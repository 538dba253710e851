"""``benchmarks/bench_step_tail.py`` as a user runs it (its own process, one round, the paper's
law): both trees' closed loops run (the baseline unpacked from git), the step's statistics,
their ratios and the tail's make-up and where its time goes are printed, and a baseline at
HEAD applies this tree's inputs to the bit where the controller is unchanged."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_benchmark_times_both_trees_and_explains_the_tail() -> None:
    changed = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                              "controllers", "cosim"],
                             capture_output=True, text=True, check=True).stdout.strip()
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_step_tail.py"),
                           "--rounds", "1", "--laws", "paper"], capture_output=True, text=True,
                          timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r"(this|baseline) +median +([\d.]+) +p90 +([\d.]+) +p99 +([\d.]+) +max "
                      r"+([\d.]+) ms", proc.stdout)
    assert [r[0] for r in rows] == ["this", "baseline"]
    assert all(0 < float(r[1]) <= float(r[2]) <= float(r[3]) <= float(r[4]) for r in rows)
    assert re.search(r"ratio +median [\d.]+x +p99 [\d.]+x", proc.stdout)
    tail = re.search(r"slowest (\d+): iterations median (\d+) \(all steps (\d+)\), (\d+) at the "
                     r"cap of 15, (\d+) within two samples of a set-point change, (\d+) with "
                     r"the governor", proc.stdout)
    assert tail and int(tail[1]) == 16 and int(tail[4]) <= 16, proc.stdout
    spent = re.search(r"their mean ([\d.]+) ms: SQP ([\d.]+), set-point handling \(the "
                      r"governor\) ([\d.]+), the rest (-?[\d.]+)", proc.stdout)
    assert spent, proc.stdout
    mean, sqp, governor, rest = (float(v) for v in spent.groups())
    assert sqp > 0 and governor > 0 and abs(sqp + governor + rest - mean) < 0.02
    gap = float(re.search(r"largest difference between the trees ([\d.e+-]+)", proc.stdout)[1])
    if not changed:   # the same controller at HEAD: the same inputs
        assert gap == 0.0


@pytest.mark.slow
def test_the_split_replays_the_slow_solves_in_both_trees() -> None:
    """``--split``: the same slow solves of the paper's law in this tree and the baseline
    (HEAD), each iteration's time split by the SQP's timers, and no clipping that fell back
    to the full decomposition."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_step_tail.py"),
                           "--split"], capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    found = re.findall(r"(\d+) solves of >= 12 iterations, (\d+) iterations", proc.stdout)
    assert len(found) == 2 and int(found[0][0]) > 10, proc.stdout
    parts = re.search(r"per iteration \[us\]: qp ([\d.]+), hessian ([\d.]+), clip ([\d.]+), "
                      r"derivatives ([\d.]+), line_search ([\d.]+); the whole solve ([\d.]+)",
                      proc.stdout)
    assert parts, proc.stdout
    values = [float(v) for v in parts.groups()]
    assert all(v > 0 for v in values) and sum(values[:5]) <= values[5] * 1.05
    clip = re.search(r"clipping per solve: ([\d.]+) decompositions, ([\d.]+) eigenvalues "
                     r"clipped, ([\d.]+) full decompositions", proc.stdout)
    assert clip and float(clip[1]) > 0 and float(clip[3]) == 0.0, proc.stdout
