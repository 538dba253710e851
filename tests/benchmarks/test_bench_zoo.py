"""``benchmarks/bench_zoo.py`` end to end on one zoo plant, quickly (CI): the van de Vusse CSTR
with 1,500 samples of data, 2 epochs and a campaign of 2 runs per controller.

What is asserted could each go wrong: the table's row is printed and ``zoo.json`` written with
every entry; the verdict agrees with certify's exit code and the saved certificate; rho_s is a
contraction rate; the infeasible steps are counted from the run's own diagnostics after its
horizon; the campaign ran the plant's ``campaign.toml`` with the runs asked for, both
controllers on the same draws, and its IAE ratio is the one recomputed here from
``runs.parquet`` and the problem's boxes.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from controllers.problem_file import load

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_zoo.py"
PLANT = "van_de_vusse"
RUNS = 2


@pytest.mark.slow
def test_the_zoo_walkthrough_runs_on_one_plant(tmp_path: Path) -> None:
    out = tmp_path / "zoo"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, str(SCRIPT), "--plants", PLANT, "--steps", "1500",
                           "--epochs", "2", "--runs", str(RUNS), "--out", str(out)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900,
                          check=False)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "Traceback" not in proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].split()[:4] == ["plant", "train", "s", "verdict"]
    row = next(line for line in lines if line.startswith(PLANT)).split()

    (report,) = json.loads((out / "zoo.json").read_text())
    work = out / PLANT
    problem = load(work / "problem.toml")
    assert report["plant"] == PLANT and 0.0 < report["train_s"] < 900.0

    # the verdict: certify's exit code, the saved certificate, rho_s a contraction rate
    verdict = report["certify"]
    assert verdict["exit"] == (0 if verdict["certified"] else 1 if verdict["usable"] else 2)
    saved = json.loads((work / "models" / "plant_gru.json").read_text())["certificate"]
    assert saved["certified"] is verdict["certified"]
    assert 0.0 < verdict["rho_s"] < 1.0 and f"{verdict['rho_s']:.5f}" in row
    assert verdict["usable"], verdict["reasons"]          # the rest needs a robust MPC

    # the scenario runs: both ran the plant's scenario; infeasible steps after N, recounted
    mpc = report["robust-mpc"]
    results = pd.read_csv(work / "runs" / "robust-mpc" / "results.csv")
    late = results.iloc[mpc["N"]:]
    recount = int(((late["ctrl.fallback"] > 0) | late["ctrl.status"].isin([1, 2])).sum())
    assert mpc["infeasible_after_N"] == recount <= mpc["failed_after_N"] <= len(late)
    assert str(recount) in row
    for key in ("robust-mpc", "pi"):
        assert report[key]["status"] == "ok" and report[key]["steps"] == len(results) - 1
        assert math.isfinite(report[key]["iae_sum"]) and report[key]["iae_sum"] > 0.0

    # the campaign: the plant's spec with the runs asked for, both controllers on one draw
    camp = report["campaign"]
    runs = pd.read_parquet(work / "campaign" / "runs.parquet")
    assert sorted(runs["variant"].unique()) == ["pi", "robust-mpc"]
    assert (runs.groupby("variant").size() == RUNS).all()
    draws = [c for c in runs.columns if c.startswith("plant.")]
    assert draws and all(runs.groupby("run")[c].nunique().eq(1).all() for c in draws)
    summed = {v: sum(sum(r[f"iae.{c.name}"] / (c.max - c.min) for c in problem.outputs)
                     for _, r in df.iterrows()) for v, df in runs.groupby("variant")}
    ratio = summed["robust-mpc"] / summed["pi"]
    assert np.isfinite(ratio) and camp["iae_ratio"] == pytest.approx(ratio, rel=1e-12)
    assert f"{ratio:.3f}" in row
    assert camp["failed"] == 0 and camp["variants"]["pi"]["failed"] == 0
