"""``controllers.shadow.PredictionWatch``: the k-step prediction errors, scored all at once,
are those of scoring each pending prediction in turn, to the bit."""

from __future__ import annotations

import numpy as np

from controllers.shadow import PredictionWatch


def _one_at_a_time(steps: list[tuple[np.ndarray, np.ndarray]], N: int, p: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The errors' sums, squares and counts, each pending prediction scored in turn."""
    pending: list[np.ndarray] = []
    total, sq, count = np.zeros((N, p)), np.zeros((N, p)), np.zeros(N, dtype=int)
    for y, pred in steps:
        for age, old in enumerate(reversed(pending[-N:])):
            if age < old.shape[0]:
                e = y - old[age]
                total[age] += e
                sq[age] += e * e
                count[age] += 1
        pending.append(pred[:N])
    return total, sq, count


def test_scored_at_once_as_one_at_a_time() -> None:
    rng = np.random.default_rng(7)
    N, p = 6, 2
    steps = [(rng.normal(size=p), rng.normal(size=(int(rng.integers(1, N + 3)), p)))
             for _ in range(40)]   # some plans shorter than N, some longer
    watch = PredictionWatch(["a", "b"], N)
    for y, pred in steps:
        watch.measure(y)
        watch.predict(pred)
    total, sq, count = _one_at_a_time(steps, N, p)
    assert np.array_equal(watch._sum, total) and np.array_equal(watch._sq, sq)
    assert np.array_equal(watch._count, count)
    last = steps[-1][1][:N]
    assert watch.last_prediction() == {"a": last[:, 0].tolist(), "b": last[:, 1].tolist()}
    assert watch.summary()["steps"] == 40
    assert PredictionWatch(["a"], 3).last_prediction() == {}
