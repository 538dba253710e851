"""The operator's settings (controllers.operator): what is refused in the user's words, what
the plant gets, how the active limits ramp, what the FHOCP is given."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controllers.operator import AUTO, MANUAL, Operator, row_narrowing
from controllers.problem import output_constraints
from tests.fourtank_problem import FOURTANK

QA_MAX, QB_MAX = 9.05e-4, 11.1e-4


def _problem(max_move: float | None = None, limit_rate: float | None = None):
    ins = tuple(dataclasses.replace(c, max_move=max_move) for c in FOURTANK.inputs)
    outs = tuple(dataclasses.replace(c, limit_rate=limit_rate) for c in FOURTANK.outputs)
    return dataclasses.replace(FOURTANK, inputs=ins, outputs=outs)


def test_refusals_name_the_setting_and_the_box() -> None:
    op = Operator(_problem())
    assert op.refuse("op.max.qa", 2e-3) == ("an operator limit 0.002 m3/s of qa is outside "
                                            "the engineer's box [0, 0.000905] m3/s")
    assert "not below high" in op.refuse("op.min.h1", 2.0)
    assert op.refuse("op.mode", 0.5) == "expected auto or manual (1 or 0)"
    assert op.refuse("op.service.qx", 0).startswith("no operator setting 'op.service.qx'")
    assert op.refuse("op.manual.qb", float("nan")) == ""
    pi = Operator(_problem(), no_output_limits="no outputs here")
    assert pi.refuse("op.max.h1", 1.0) == "no outputs here"
    assert "op.max.h1" not in pi.names() and "op.max.qa" in pi.names()


def test_the_plant_gets_the_operators_the_held_and_the_limited_inputs() -> None:
    op = Operator(_problem(max_move=1e-4))
    start = np.array([4e-4, 5e-4])
    assert not op.engaged or op.moves   # a declared move limit engages every step
    first = op.applied(np.array([8e-4, 9e-4]), start)      # no last input: unlimited
    assert first.tolist() == [8e-4, 9e-4]
    op.set("op.mode", MANUAL)
    op.set("op.manual.qa", 3e-4)
    manual = op.applied(np.array([1e-5, 1e-5]), start)
    assert manual.tolist() == [3e-4, 9e-4]                  # qa the operator's, qb held
    op.set("op.mode", AUTO)
    op.set("op.service.qb", 0)
    auto = op.applied(np.array([8e-4, 1e-5]), start)
    assert auto[0] == pytest.approx(4e-4) and auto[1] == 9e-4   # moved max_move, qb held
    op.set("op.max.qa", 4.5e-4)                              # narrower: it ramps
    assert op.value("op.max.qa") == 4.5e-4 and op.u_active[0, 1] == QA_MAX
    op.ramp()
    assert op.u_active[0, 1] == pytest.approx(QA_MAX - 1e-4)


def test_output_limits_ramp_within_the_room_and_the_rate() -> None:
    op = Operator(_problem(limit_rate=0.05))
    op.set("op.max.h1", 1.0)
    op.ramp(None)                                  # no plan to keep: held
    assert op.y_active[0, 1] == 2.0
    op.ramp(np.array([[np.inf, 0.02], [np.inf, np.inf]]))
    assert op.y_active[0, 1] == pytest.approx(1.98)   # the room
    op.ramp(np.full((2, 2), np.inf))
    assert op.y_active[0, 1] == pytest.approx(1.93)   # the rate
    op.set("op.max.h1", 2.0)                          # wider: at once
    assert op.y_active[0, 1] == 2.0


def test_the_fhocp_gets_normalised_bounds_and_row_narrowing() -> None:
    op = Operator(_problem(max_move=1e-4))
    scale = np.array([QA_MAX / 2, QB_MAX / 2])
    offset = scale.copy()
    op.applied(np.array([4e-4, 5e-4]), offset)
    op.set("op.service.qb", 0)
    op.set("op.max.qa", 8.5e-4)
    op.ramp()                                     # one max_move reaches it
    terms = op.terms(scale, offset, offset, np.zeros(4))
    last = (np.array([4e-4, 5e-4]) - offset) / scale
    assert terms.lo0[0] == pytest.approx(last[0] - 1e-4 / scale[0])
    assert terms.hi[0] == pytest.approx((8.5e-4 - offset[0]) / scale[0])
    assert terms.lo[1] == terms.hi[1] == terms.lo0[1] == pytest.approx(last[1])
    lbx, ubx = np.full(6, -1.0), np.full(6, 1.0)
    terms.bound(lbx, ubx, np.arange(6).reshape(3, 2))
    assert ubx[0] == pytest.approx(terms.hi0[0]) and lbx[3] == ubx[3]

    class Model:
        output_names = FOURTANK.output_names
        y_offset, y_scale = np.ones(2), np.ones(2)

    L, h = output_constraints(Model(), FOURTANK)
    delta = row_narrowing(L, h, np.array([-1.0, -1.0]), np.array([0.0, 1.0]))
    assert delta.tolist() == [1.0, 0.0, 0.0, 0.0]   # h1 <= 1 m: its upper row narrowed by 1
