"""The robust MPC's ``du_weight`` option (the input-rate penalty, controllers.ocp.input_rate): per
input by name, reported in the summary, and smoother inputs in closed loop on the paper
scenario with the four-tank FMU."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from cosim.adapters.robust_mpc import RobustMPCController
from cosim.api import run

ROOT = Path(__file__).resolve().parents[3]


def test_weights_by_input_name_and_in_the_summary() -> None:
    c = RobustMPCController(du_weight={"qb": 5})
    assert np.array_equal(c.mpc.fhocp.du_weight, [0.0, 5.0]) and c.mpc.fhocp.has_du
    assert c.summary()["du_weight"] == {"qa": 0.0, "qb": 5.0}
    d = RobustMPCController(law="paper")          # the paper's cost has no input-rate term
    assert not d.mpc.fhocp.has_du and d.summary()["du_weight"] == {"qa": 0.0, "qb": 0.0}
    assert RobustMPCController().summary()["du_weight"] == {"qa": 0.05, "qb": 0.05}
    assert np.array_equal(RobustMPCController(du_weight=2).mpc.fhocp.du_weight, [2.0, 2.0])


@pytest.fixture(scope="module")
def paper_start(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper scenario's first six set-points (four steps up, then h1 down from 1.2 to
    0.8 m, where the paper's law moves its inputs most; 600 samples)."""
    rows = (ROOT / "scenarios" / "paper_steps.csv").read_text().splitlines()
    assert rows[:7] == ["time,ref.h1,ref.h2", "0,0.65,0.65", "2500,0.9,", "5000,,1.0",
                        "7500,1.2,", "10000,,1.3", "12500,0.8,"]
    path = tmp_path_factory.mktemp("du") / "paper_start.csv"
    path.write_text("\n".join([*rows[:7], "15000,,"]) + "\n")
    return path


def test_a_larger_weight_moves_the_inputs_less(paper_start: Path) -> None:
    """Total variation of each input (``tv.<input>``, m³/s) falls as the weight grows, with
    no constraint violation and the outputs still tracked."""
    tv, iae = [], []
    for weight in (0.0, 3.0, 30.0):
        out = run(paper_start, options={"du_weight": weight}, figure=False)
        assert out.status == "ok", out.reason
        k = out.summary["kpis"]
        assert all(v["count"] == 0 for v in k["violations"].values())
        assert out.summary["controller_summary"]["du_weight"] == {"qa": weight, "qb": weight}
        tv.append((k["tv"]["qa"], k["tv"]["qb"]))
        iae.append(k["iae"]["h1"] + k["iae"]["h2"])
    for a, b in itertools.pairwise(tv):
        assert b[0] < a[0] and b[1] < a[1], tv
    assert tv[-1][0] < 0.7 * tv[0][0] and tv[-1][1] < 0.7 * tv[0][1], tv
    assert iae[-1] < 1.5 * iae[0], iae    # slower, not lost
