"""Measured disturbances and dead time in the numerical core: the problem file declares them
(each fault one line naming file and line), the model's inputs are shifted by their dead
time, the GRU conditioned on a held disturbance is the full GRU, the static feedforward
keeps the outputs, and the certificate's bounds and held-disturbance term come from the full
model (lem:held-disturbance)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import gru
from controllers.dead_time import DelayLine, InputPrefix, delayed
from controllers.disturbances import (
    BiasShift,
    condition,
    feedforward_gain,
    held_error,
    input_gain,
)
from controllers.equilibrium import equilibrium_for_output, state_equilibrium
from controllers.errors import ProblemFileError
from controllers.problem import Channel, ControlProblem
from controllers.problem_file import load, loads, problem_from_dict
from tests.controllers.random_gru import random_gru_model
from tests.heater_problem import HEATER

#: the heater whose power acts two samples late
TOML = HEATER.replace("hold = [3, 60]", "delay = 2")


def heater_problem(**dist: object) -> ControlProblem:
    return ControlProblem(
        name="heater", Ts=20.0, inputs=(Channel("P", "W", 0.0, 2000.0),),
        outputs=(Channel("T", "degC", 15.0, 80.0),),
        disturbances=(Channel("T_in", "degC", 5.0, 35.0, **dist),))  # type: ignore[arg-type]


# -- the problem file ---------------------------------------------------------------------------
def test_a_problem_file_declares_disturbances_and_dead_time(tmp_path) -> None:
    path = tmp_path / "heater.toml"
    path.write_text(TOML)
    problem = load(path)
    assert problem.disturbance_names == ("T_in",) and problem.q == 1 and problem.m == 1
    assert problem.model_input_names == ("P", "T_in")
    assert problem.delays == (2, 0)
    d = problem.channel("T_in")
    assert (d.variable, d.rate, d.preview, d.hold) == ("T_amb", 0.5, False, (5, 80))
    assert problem.normalization()["u_offset"].tolist() == [1000.0, 20.0]
    assert "measured: T_in [degC]" in problem.describe() and "+2 samples" in problem.describe()
    # the JSON form (model file, data sidecar) round-trips, and a changed delay is a difference
    back = problem_from_dict(problem.to_dict(), "m.json")
    assert back == problem and not problem.differences(back)
    other = loads(TOML.replace("delay = 2", "delay = 3"), "other.toml")
    assert problem.differences(other) == ["P.delay 2 vs 3"]


@pytest.mark.parametrize(("edit", "line", "words"), [
    (("delay = 2", "delay = 2.5"), 9, "'delay' must be a whole number of samples from 0 to 50"),
    (("delay = 2", "delay = 51"), 9, "from 0 to 50, got 51"),
    (("delay = 2", "delay = -1"), 9, "got -1"),
    (("rate = 0.5", "rate = 31"), 21, "must be in (0, max - min = 30], got 31"),
    (("rate = 0.5", "rate = 0"), 21, "got 0"),
    (("rate = 0.5", "preview = 1"), 21, "'preview' must be true or false"),
    (("[outputs.T]\n", "[outputs.T]\npreview = true\n"), 12,
     "unknown key 'preview' in [outputs.T] (preview is for disturbances)"),
    (("[outputs.T]\n", "[outputs.T]\ndelay = 1\n"), 12, "unknown key 'delay' in [outputs.T]"),
    (("variable = \"T_amb\"", "variable = \"P\""), 16, "variable 'P' is used twice"),
    (("[disturbances.T_in]", "[disturbances.T]"), 16, "name 'T' is used twice"),
    (("max = 35.0", "max = 5.0"), 19, "needs min < max"),
])
def test_a_bad_disturbance_is_one_line_naming_the_line(edit: tuple[str, str], line: int,
                                                      words: str) -> None:
    with pytest.raises(ProblemFileError) as info:
        loads(TOML.replace(*edit), "heater.toml")
    msg = str(info.value)
    assert msg.startswith(f"heater.toml:{line}:") and words in msg and "\n" not in msg


# -- dead time ----------------------------------------------------------------------------------
def test_delayed_shifts_each_column_within_each_experiment() -> None:
    u = np.arange(12, dtype=float).reshape(6, 2)
    v = delayed(u, [2, 0], np.array([0, 0, 0, 1, 1, 1]))
    assert v[:, 1].tolist() == u[:, 1].tolist()
    # experiment 0: rows 0..2; experiment 1: rows 3..5, each starting at its first value
    assert v[:, 0].tolist() == [0.0, 0.0, 0.0, 6.0, 6.0, 6.0]
    assert delayed(u, [1, 0])[:, 0].tolist() == [0.0, 0.0, 2.0, 4.0, 6.0, 8.0]
    with pytest.raises(ValueError):
        delayed(u, [1])


def test_a_delay_line_gives_the_model_input_and_the_known_ones_ahead() -> None:
    line = DelayLine([2, 0])
    for k in range(5):
        line.push(np.array([10.0 + k, 20.0 + k]))
    # the newest push is sample 4: v_4 = (s_2, s_4); one sample ahead the first is s_3
    assert line.current().tolist() == [12.0, 24.0]
    with pytest.raises(ValueError):
        line.ahead(1)   # past the second signal's (zero) delay
    only = DelayLine([2])
    only.push(np.array([1.0]))
    assert only.current().tolist() == [1.0]   # before enough pushes: the first value (at rest)
    only.push(np.array([2.0]))
    only.push(np.array([3.0]))
    assert [only.ahead(i).item() for i in range(3)] == [1.0, 2.0, 3.0]


# -- the conditioned GRU ------------------------------------------------------------------------
def test_the_conditioned_gru_is_the_full_gru_with_the_disturbance_held() -> None:
    model = random_gru_model(3, n=8, problem=heater_problem(rate=0.5))
    d = np.array([0.4])
    cond = condition(model, d)
    assert cond.m == 1 and cond.held_from is model and cond.problem.q == 0
    u = np.random.default_rng(1).uniform(-1, 1, (30, 1))
    x0 = np.zeros(8)
    x_full = gru.simulate(model.params, x0, np.hstack([u, np.tile(d, (30, 1))]))[0]
    x_cond = gru.simulate(cond.params, x0, u)[0]
    assert np.max(np.abs(x_full - x_cond)) < 1e-14
    # the shift moves the biases in place, and back
    nominal = condition(model)
    biases = {b: nominal.params[b] for b in ("b_z", "b_r", "b_h")}
    shift = BiasShift(model, nominal.params)
    assert shift.set(d) and not shift.set(d)
    assert all(nominal.params[b] is biases[b] for b in biases)
    assert np.max(np.abs(gru.simulate(nominal.params, x0, u)[0] - x_full)) < 1e-14
    assert shift.delta.shape == (24,)
    shift.set(np.zeros(1))
    assert np.max(np.abs(nominal.params["b_z"] - model.params["b_z"])) == 0.0


def test_the_static_feedforward_keeps_the_output_where_it_was() -> None:
    model = random_gru_model(5, n=8, problem=heater_problem())
    cond = condition(model)
    x, u = equilibrium_for_output(cond.params, np.array([0.1]))
    K = feedforward_gain(model, x, np.concatenate([u, [0.0]]))
    dd = 0.01
    moved = condition(model, np.array([dd]))
    y0 = gru.output(model.params, x)
    for gain, better in ((K, True), (np.zeros_like(K), False)):
        xs = state_equilibrium(moved.params, u + gain @ [dd], x)
        err = abs(float((gru.output(model.params, xs) - y0)[0]))
        assert (err < 1e-5) is better, (gain, err)


def test_the_certificate_of_the_conditioned_model_is_the_full_models() -> None:
    from controllers.certification.bounds import nu
    from controllers.certification.certificates import compute_certificate

    model = random_gru_model(0, n=10, problem=heater_problem(rate=0.3))
    model.w_y_bar = 0.01
    cond = condition(model)
    cert = compute_certificate(cond, N=15, gain_scale=0.0)
    assert cert.nu == pytest.approx(nu(model.params)) and cert.nu >= nu(cond.params)
    assert cert.params["W_z"].shape == (10, 1) and cert.R.shape == (1, 1)
    # the held disturbance's term: zero while the held value is exact (the first step),
    # then growing; part of b
    e = held_error(model, cert.rho_s, 15)
    assert e[:2].tolist() == [0.0, 0.0] and np.all(np.diff(e[1:]) > 0)
    assert cert.b_held is not None and np.allclose(cert.b_held, e[:, None] * cert.c_s[None])
    assert input_gain(model) > 0
    # with a dead time on the disturbance its first samples are known: predicted over the
    # inputs' dead time (K = 3) with them, no term there; the FHOCP holds d_k, exact at its
    # first stage (i = 3 = L), then apart
    late = random_gru_model(0, n=10, problem=heater_problem(rate=0.3, delay=3))
    assert held_error(late, cert.rho_s, 15, K=3)[:5].tolist() == [0.0] * 5
    assert held_error(late, cert.rho_s, 15, K=3)[5] > 0
    # without input dead time the FHOCP's first stages see d_{k-3} .. d_{k-1}, not d_k
    assert held_error(late, cert.rho_s, 15)[1] > 0
    # no contraction: the term is infinite once the disturbance can have moved
    assert np.isinf(held_error(model, 1.0, 5)[2:]).all()


def test_dead_time_shifts_the_tightening_by_its_samples() -> None:
    from controllers.certification.certificates import compute_certificate
    from controllers.certification.prediction_error import margins
    from controllers.dead_time import input_delay, input_lags

    plain = random_gru_model(0, n=10, problem=heater_problem(rate=0.3))
    late = random_gru_model(0, n=10, problem=ControlProblem(
        name="heater", Ts=20.0, inputs=(Channel("P", "W", 0.0, 2000.0, delay=3),),
        outputs=(Channel("T", "degC", 15.0, 80.0),),
        disturbances=(Channel("T_in", "degC", 5.0, 35.0, rate=0.3),)))
    for model in (plain, late):
        model.w_y_bar = 0.01
    assert input_delay(late.problem) == 3 and input_delay(plain.problem) == 0
    long = compute_certificate(condition(plain), N=18, gain_scale=0.0)
    short = compute_certificate(condition(late), N=15, gain_scale=0.0)
    # the FHOCP's stage i is 3 + i steps after the estimate: the theorem's terms 3 steps on
    assert np.allclose(short.a, long.a[3:]) and np.allclose(short.b, long.b[3:])
    assert np.allclose(short.b_held, long.b_held[3:])
    profile = np.arange(10.0)[:, None]
    assert margins(profile, np.ones((1, 1)), 4, shift=3)[:, 0].tolist() == [3, 4, 5, 6, 7]
    assert margins(profile, np.ones((1, 1)), 8, shift=3)[-1, 0] == 9.0   # the last holds
    mixed = ControlProblem(name="x", Ts=1.0, inputs=(Channel("a", "1", 0.0, 1.0, delay=1),
                                                     Channel("b", "1", 0.0, 1.0, delay=3)),
                           outputs=(Channel("y", "1", 0.0, 1.0),))
    assert input_delay(mixed) == 1 and input_lags(mixed) == (0, 2)


def test_an_input_prefix_fixes_the_stages_already_applied() -> None:
    """Input b acts two samples after a: its first two FHOCP inputs are the ones applied two
    and one samples ago, and the input applied now is its stage 2."""
    prefix = InputPrefix([0, 2])
    past = np.array([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])   # oldest first
    prefix.set(past)
    plan = np.arange(10.0).reshape(5, 2)
    fixed = prefix.impose(plan)
    np.testing.assert_array_equal(fixed[:, 1], [0.4, 0.6, 5.0, 7.0, 9.0])
    np.testing.assert_array_equal(fixed[:, 0], plan[:, 0])
    np.testing.assert_array_equal(prefix.applied(fixed), [0.0, 5.0])
    lbx, ubx = np.full(11, -1.0), np.full(11, 1.0)
    prefix.bound(lbx, ubx, np.arange(10).reshape(5, 2))
    assert (lbx[[1, 3]] == ubx[[1, 3]]).all() and lbx[1] == 0.4 and lbx[3] == 0.6
    assert (lbx[[0, 2, 4, 5, 10]] == -1.0).all() and (ubx[[0, 2, 5, 10]] == 1.0).all()
    none = InputPrefix([0, 0])
    none.set(past)
    assert none.impose(plan) is plan and none.applied(plan).tolist() == [0.0, 1.0]
