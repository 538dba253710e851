"""The decentralised PI baseline: saturation, anti-windup, sign, closed loop on the FMU."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.adapters.pi import PIController, PILoop
from cosim.core.fmu import FmuComponent
from cosim.core.master import Master
from cosim.core.scenario import load
from tests.fourtank_problem import FOURTANK


def step(pi: PIController, h1: float, h2: float, r1: float, r2: float) -> dict[str, float]:
    pi.set_inputs({"h1": h1, "h2": h2, "ref.h1": r1, "ref.h2": r2})
    pi.step(0.0, 25.0)
    return pi.get_outputs()


def test_interface() -> None:
    pi = PIController()
    assert pi.direct_feedthrough and pi.sample_time == 25.0
    assert [s.name for s in pi.outputs] == ["qa", "qb"]
    assert {s.name for s in pi.inputs} == {"h1", "h2", "ref.h1", "ref.h2"}
    assert pi.bounds == FOURTANK.bounds()


def test_error_sign_follows_the_pairing() -> None:
    pi = PIController()  # h1 <- qb, h2 <- qa
    u0 = step(PIController(), 1.0, 1.0, 1.0, 1.0)
    u = step(pi, 0.9, 1.0, 1.0, 1.0)  # h1 below its set-point
    assert u["qb"] > u0["qb"] and u["qa"] == u0["qa"]


def test_saturation_and_anti_windup() -> None:
    pi = PIController()
    lo, hi = FOURTANK.bounds()["qb"]
    for _ in range(2000):  # a long, unreachable demand
        u = step(pi, 0.0, 1.0, 2.0, 1.0)
        assert lo <= u["qb"] <= hi and lo <= u["qa"] <= FOURTANK.bounds()["qa"][1]
    assert u["qb"] == hi
    # back-calculation keeps the integrator near the bound: it leaves saturation at once
    u = step(pi, 2.1, 1.0, 2.0, 1.0)
    assert u["qb"] < hi
    assert pi.summary()["saturated_steps"]["qb"] >= 1999

    no_aw = PIController(loops=[PILoop(lp.y, lp.u, lp.K, lp.Ti, 1e12)
                                for lp in FOURTANK.pairings["cross"]])
    for _ in range(2000):
        step(no_aw, 0.0, 1.0, 2.0, 1.0)
    assert step(no_aw, 2.1, 1.0, 2.0, 1.0)["qb"] == hi  # wound up: still saturated


@pytest.mark.parametrize("pairing", ["cross", "diagonal"])
def test_closed_loop_on_the_fmu(tmp_path: Path, fmu2_path: Path, pairing: str) -> None:
    path = tmp_path / "steps.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.8,0.7\n5000,1.1,0.9\n15000,,\n")
    result = Master(FmuComponent(fmu2_path), PIController(pairing=pairing), load(path)).run()
    assert result.status == "ok"
    data = np.asarray(result.rows)
    h1, h2 = data[:, result.columns.index("plant.h1")], data[:, result.columns.index("plant.h2")]
    if pairing == "cross":
        assert abs(h1[-1] - 1.1) < 2e-3 and abs(h2[-1] - 0.9) < 2e-3
        assert abs(h1[199] - 0.8) < 5e-3 and abs(h2[199] - 0.7) < 5e-3
    else:  # the negative-RGA pairing: stable with its tuning, but far slower
        err = np.abs(h1 - 1.1)[-40:].max()
        assert err > 2e-3


@pytest.mark.parametrize("kwargs, message", [
    ({"pairing": "sideways"}, "unknown pairing 'sideways' (the problem's: cross, diagonal)"),
    ({"loops": [{"output": "h1", "input": "qa", "K": 1.0}]},
     "loops: each loop is {output, input, K, Ti, Tt}"),
    ({"loops": [{"output": "h1", "input": "qa", "K": 1.0, "Ti": 10.0}]},
     "loops must pair each output (h1, h2) with one input (qa, qb), got h1-qa"),
    ({"loops": [], "pairing": "cross"}, "give loops or pairing, not both"),
    ({"initial_inputs": [1, 2]}, "initial_inputs must map inputs to numbers"),
    ({"initial_inputs": {"qz": 1e-4}}, "initial_inputs: unknown input 'qz' (inputs: qa, qb)"),
    ({"initial_inputs": {"qa": "x"}}, "initial_inputs: qa must be a finite number, got 'x'"),
    ({"initial_inputs": {"qa": float("nan")}}, "initial_inputs: qa must be a finite number"),
])
def test_bad_options_are_one_line_errors(kwargs, message) -> None:
    from cosim.core.errors import CosimError

    with pytest.raises(CosimError) as info:
        PIController(**kwargs)
    assert str(info.value).startswith("controller 'pi': ") and message in str(info.value)


def test_initial_inputs_start_the_integrators() -> None:
    ctrl = PIController(initial_inputs={"qa": 4e-4})
    assert ctrl._u["qa"] == 4e-4 and ctrl.initial_inputs == {"qa": 4e-4}
    assert PIController(pairing="diagonal").loops == FOURTANK.pairings["diagonal"]
    given = [lp.to_dict() for lp in FOURTANK.pairings["diagonal"]]
    assert PIController(loops=given).loops == FOURTANK.pairings["diagonal"]
