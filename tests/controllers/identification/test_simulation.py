"""Identification by simulation error (``controllers.identification.simulation``) and the
search over sizes and seeds (``controllers.identification.search``): the fit improves the
free run, stays δISS, is deterministic, and the search's answer does not depend on how many
worker processes fit the candidates."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("torch")

from controllers.certification.bounds import nu
from controllers.identification.initial_state import free_run
from controllers.identification.record import Record
from controllers.identification.search import candidates, search
from controllers.identification.simulation import (
    SimOptions,
    fit_candidate,
    rms,
    simulate,
    training_windows,
)
from controllers.identification.training import init_params


@pytest.fixture(scope="module")
def record() -> Record:
    """A GRU plant (4 states) driven by steps, 600 rows, one output saturating at its top:
    450 train / 75 val / 75 test, two experiments."""
    rng = np.random.default_rng(0)
    plant = init_params(4, 1, 1, 11, bz_init=1.0)
    plant["U_h"] *= 3.0
    u = np.repeat(rng.uniform(-1, 1, (60, 1)), 10, axis=0)
    y = np.concatenate([free_run(plant, u[:300], rng.uniform(-0.5, 0.5, 4)),
                        free_run(plant, u[300:], rng.uniform(-0.5, 0.5, 4))])
    y = 2.0 * (y - y.mean()) / (y.max() - y.min())
    y = np.minimum(y, np.quantile(y, 0.95))          # 5 % of the samples at a sensor limit
    one = np.repeat(["train", "val", "test"], [225, 38, 37])
    return Record(u, y, np.concatenate([one, one]), np.repeat([0, 1], 300))


def test_windows_follow_the_training_stretches(record: Record) -> None:
    assert training_windows(record) == [(0, 225), (300, 525)]
    assert training_windows(record, window=100) == [(0, 112), (112, 225), (300, 412),
                                                    (412, 525)]
    assert record.limits.upper[0] is not None       # the plateau was found


def test_the_fit_improves_the_free_run_stays_delta_iss_and_repeats(record: Record) -> None:
    opt = SimOptions(n=6, epochs=60, seed=3, polish=0)
    start = init_params(6, 1, 1, 3)
    before = rms(record, simulate(start, record))["val"][0]
    cand = fit_candidate(record, opt)
    after = rms(record, simulate(cand.params, record))["val"][0]
    assert after < 0.5 * before and cand.score == pytest.approx(after, rel=1e-12)
    assert nu(cand.params) <= 1 - opt.nu_margin + 1e-12 and cand.nu < 1
    assert 0 <= cand.best_step <= opt.steps and cand.steps_run == opt.steps
    again = fit_candidate(record, opt)
    assert all(np.array_equal(cand.params[k], again.params[k]) for k in cand.params)


def test_lbfgs_after_adam_lowers_the_score_within_the_contraction_cap(record: Record) -> None:
    """The polish (controllers.identification.polish) continues from Adam's best: a lower
    validation score, every evaluation δISS with ρ_s ≤ rho_max (lem:Vs)."""
    from controllers.certification.bounds import rho_s

    opt = SimOptions(n=4, epochs=20, seed=1, rho_max=0.9, polish=0)
    adam = fit_candidate(record, opt)
    both = fit_candidate(record, replace(opt, polish=150))
    assert both.score < 0.8 * adam.score and both.best_step > opt.steps
    assert rho_s(both.params) <= 0.9 + 1e-12 and rho_s(adam.params) <= 0.9 + 1e-12
    assert opt.steps < both.steps_run <= opt.total + 150


def test_the_search_answer_does_not_depend_on_the_workers(record: Record) -> None:
    """Each seed's lane grows the size while it pays (here never: the lanes stop after their
    second size), the same candidates whatever the workers."""
    base = SimOptions(epochs=4, seed=5, polish=10)
    todo = candidates(base, (3, 2, 4), 2)
    assert [(o.n, o.seed) for o in todo][:4] == [(2, 5), (2, 6), (3, 5), (3, 6)]
    steps: list[int] = []
    one = search(record, base, (3, 2, 4), 2, workers=1, progress=steps.append, growth=1.0)
    two = search(record, base, (3, 2, 4), 2, workers=2, growth=1.0)
    assert [(t["n"], t["seed"]) for t in one.tried] == [(2, 5), (2, 6), (3, 5), (3, 6)]
    assert [t["score"] for t in one.tried] == [t["score"] for t in two.tried]
    assert one.best.score == min(t["score"] for t in one.tried)
    assert all(np.array_equal(one.best.params[k], two.best.params[k]) for k in one.best.params)
    assert steps[-1] == 6 * base.total


def test_a_lane_tries_the_cap_and_none_at_its_smallest_size(record: Record) -> None:
    """With ``loose``: the smallest size fitted under the cap and without it, the lane grown
    under the one kept; the model kept is the capped one unless the other is better by
    PREFER_CAPPED."""
    from controllers.identification.search import PREFER_CAPPED, planned_steps

    base = SimOptions(epochs=4, seed=2, polish=10, rho_max=0.9)
    res = search(record, base, (2, 3), 1, workers=1, loose=0.0)
    first = [(t["n"], t["rho_max"]) for t in res.tried if t["n"] == 2]
    assert sorted(first) == [(2, 0.0), (2, 0.9)] and len(res.tried) <= 3
    scores = {float(k): v for k, v in res.caps["scores"].items()}
    loose_wins = scores[0.0] < (1 - PREFER_CAPPED) * scores[0.9]
    assert res.caps["kept"] == (0.0 if loose_wins else 0.9)
    assert res.best.score == scores[res.caps["kept"]]
    assert planned_steps(base, (2, 3), 1, 0.0) == 3 * base.total
