"""The examples in ``examples/`` run as a user runs them: each script, in its own process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
#: Examples run with more options, or by a test of their own: own_plant.py (the whole
#: pipeline on a plant that is not four tanks) runs per plant in tests/test_example_plants.py;
#: tracking_theorem.py (the checker of a finished tracking_theorem campaign) checks the two
#: runs of that campaign in tests/cosim/campaign/test_shipped_campaigns.py.
ELSEWHERE = {"own_plant", "tracking_theorem"}


def test_examples_are_shipped() -> None:
    assert {p.stem for p in EXAMPLES} >= {"closed_loop", "own_plant", "campaign"}


@pytest.mark.slow
@pytest.mark.parametrize("script", [p for p in EXAMPLES if p.stem not in ELSEWHERE],
                         ids=lambda p: p.stem)
def test_example_runs(script: Path, tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(script), "--out", str(tmp_path / "out")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "status ok" in proc.stdout or "0 failed" in proc.stdout, proc.stdout
    assert "Traceback" not in proc.stderr
