"""``cosim run --plant opc.tcp://...`` against ``cosim serve-plant``: the same closed loop as
the in-process co-simulation (goal: to 1e-6 of each signal's range), tags, bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cosim
from cosim.live.runner import LiveOptions
from tests.cosim.live import ua
from tests.cosim.live.conftest import cosim as cli
from tests.cosim.live.conftest import env, free_port, served

SPEED = 250.0      # the four-tank's Ts = 25 s: one sample every 0.1 s
RANGES = {"plant.h1": 2.0, "plant.h2": 2.0, "ctrl.qa": 9.05e-4, "ctrl.qb": 11.1e-4}


def parity(tmp_path: Path, scenario: Path, controller: str) -> dict:
    """Run ``controller`` against a frozen served plant and in-process; the live summary
    after checking that both closed loops agree. The parity needs every sample fresh and on
    time: a live run that a loaded machine delayed (a stale sample, a missed deadline, a
    plant sample read twice: seen in CI runs whose other worker was compiling) is run once
    more."""
    for attempt in range(2):
        if attempt:   # the first attempt's folder and record go
            shutil.rmtree(tmp_path / "live")
            (tmp_path / "plant.csv").unlink(missing_ok=True)
        with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--frozen",
                    "--record", str(tmp_path / "plant.csv")) as s:
            live = cosim.run(scenario, plant=s.endpoint, controller=controller,
                             out=tmp_path / "live", live=LiveOptions(speed=SPEED),
                             figure=False)
        assert live.status == "ok", live.reason
        lv = live.summary["live"]
        if attempt == 0 and (lv["deadline_misses"] or lv["stale"] or lv["repeated"]):
            continue
        break
    ref = cosim.run(scenario, controller=controller, out=tmp_path / "ref", figure=False)
    assert lv["deadline_misses"] == 0 and lv["stale"] == 0 and lv["phase_locked"], lv
    a, b = live.to_pandas(), ref.to_pandas()
    assert len(a) == len(b) == 61
    for col, span in RANGES.items():
        err = np.max(np.abs(a[col].to_numpy() - b[col].to_numpy())) / span
        assert err <= 1e-6, (col, err)
    # the plant's own record agrees: it applied what the controller wrote
    plant = pd.read_csv(tmp_path / "plant.csv")
    n = len(plant)
    assert n >= 60
    for col in ("ctrl.qa", "plant.h1"):
        assert np.allclose(plant[col].to_numpy()[:60], b[col].to_numpy()[:60], rtol=0,
                           atol=1e-9 * RANGES[col])
    return lv


@pytest.mark.slow
def test_robust_mpc_same_closed_loop_as_cosimulation(tmp_path: Path,
                                                     short_scenario: Path) -> None:
    lv = parity(tmp_path, short_scenario, "robust-mpc")
    summary = json.loads((tmp_path / "live" / "summary.json").read_text())
    assert summary["live"]["latency_ms"]["loop"]["p99"] < 1e3 * 0.8 * 25.0 / SPEED
    assert summary["plant"].startswith("opc.tcp://") and lv["security"] == "None"
    timings = pd.read_csv(tmp_path / "live" / "timings.csv")
    assert {"live.read_ms", "live.compute_ms", "live.write_ms", "live.late_ms",
            "ctrl.solve_ms"} <= set(timings.columns)
    results = pd.read_csv(tmp_path / "live" / "results.csv")
    assert (results["live.fresh"] == 1).all() and (results["live.written"] == 1).all()


@pytest.mark.slow
def test_controller_fmu_same_closed_loop_as_cosimulation(
        tmp_path: Path, short_scenario: Path, controller_fmus: dict[int, Path]) -> None:
    parity(tmp_path, short_scenario, str(controller_fmus[3]))


@pytest.mark.slow
def test_pi_same_closed_loop_and_tags(tmp_path: Path, short_scenario: Path) -> None:
    tags = tmp_path / "plant.tags.toml"
    tags.write_text('root = "/2:fourtank"\n[tags]\nh1 = "ns=2;s=fourtank.h1"\n'
                    'h2 = "/2:fourtank/2:h2"\nqa = "qa"\n')
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--frozen") as s:
        live = cosim.run(short_scenario, plant=s.endpoint, controller="pi", figure=False,
                         live=LiveOptions(speed=SPEED, tags=tags))
    ref = cosim.run(short_scenario, controller="pi", figure=False)
    assert live.summary["live"]["deadline_misses"] == 0
    a, b = live.to_pandas(), ref.to_pandas()
    for col, span in RANGES.items():
        assert np.max(np.abs(a[col].to_numpy() - b[col].to_numpy())) <= 1e-6 * span


def test_bad_input_is_one_line_and_writes_nothing(tmp_path: Path, short_scenario: Path) -> None:
    port = free_port()
    url = f"opc.tcp://127.0.0.1:{port}"
    perturbed = tmp_path / "perturbed.csv"
    perturbed.write_text("time,ref.h1,ref.h2,plant.gamma_a\n0,0.65,0.65,0.3\n100,,,\n")
    bad_tags = tmp_path / "bad.tags.toml"
    bad_tags.write_text("[tags]\nlevel = \"x\"\n")
    cases = [
        ([url], "--security: required"),
        ([url, "--security", "None", "--tags", str(bad_tags)],
         f"{bad_tags}:2: 'level' is not a signal of the problem"),
        ([url, "--security", "None"], "cannot connect: connection refused"),
        ([url, "--security", "None", "--step", "5"], "--step: a live run steps at"),
        ([url, "--security", "None", "--min-controlled", "1.5"],
         "--min-controlled 1.5: must be a share from 0 to 1"),
        (["http://x", "--security", "None"], "--security: only for a live plant"),
    ]
    for extra, words in cases:
        out = tmp_path / "out"
        r = subprocess.run(cli("run", str(short_scenario), "--plant", *extra, "--out", str(out),
                               "--quiet"), env=env(), cwd=tmp_path, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 2 and words in r.stderr, (extra, r.stderr)
        assert "Traceback" not in r.stderr and not out.exists()
    r = subprocess.run(cli("run", str(perturbed), "--plant", url, "--security", "None"),
                       env=env(), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "column 'plant.gamma_a': a live plant is not set" in r.stderr
    r = subprocess.run(cli("run", str(short_scenario), "--tags", str(bad_tags)), env=env(),
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--tags: only for a live plant" in r.stderr


def test_nodes_the_run_cannot_use_are_named(tmp_path: Path, short_scenario: Path) -> None:
    """At connection, before anything is written: a tag the server lacks, a unit its
    EngineeringUnits contradict, a heartbeat node that is missing or read-only: one line
    each, exit 2."""
    tags, mm = tmp_path / "plant.tags.toml", tmp_path / "mm.tags.toml"
    tags.write_text('[tags]\nh2 = "ns=2;s=LT102.PV"\n')
    mm.write_text('[tags.h1]\nnode = "ns=2;s=fourtank.h1"\nunit = "mm"\n')
    cases = [(["--tags", str(tags)], ("signal 'h2' (ns=2;s=LT102.PV, ", "no such node")),
             (["--tags", str(mm)], ("signal 'h1' (ns=2;s=fourtank.h1): the server's unit is "
                                    "'m' (its EngineeringUnits), not the tags file's 'mm' "
                                    "(the problem's: 'm')",)),
             (["--heartbeat", "ns=2;s=fourtank.WD"], ("--heartbeat (ns=2;s=fourtank.WD, "
                                                      "--heartbeat): no such node",)),
             (["--heartbeat", "h1"], ("--heartbeat h1: at opc.tcp://",
                                      "the node is not writable by this user"))]
    with served(tmp_path, "--security", "None", "--speed", str(SPEED), "--frozen") as s:
        for extra, words in cases:
            r = subprocess.run(cli("run", str(short_scenario), "--plant", s.endpoint,
                                   "--security", "None", "--speed", str(SPEED), *extra,
                                   "--out", str(tmp_path / "out")), env=env(), cwd=tmp_path,
                               capture_output=True, text=True, timeout=120)
            error = [ln for ln in r.stderr.splitlines() if "error" in ln]
            assert r.returncode == 2 and len(error) == 1, (extra, r.stderr)
            assert all(w in error[0] for w in words), (extra, error)
            assert not (tmp_path / "out").exists()
        assert ua.read(s.endpoint, ["Simulation", "Frozen"]).Value.Value is True  # unwritten
