"""Several candidate models (sizes and seeds) fitted side by side, the best on validation kept.

A short record does not say in advance how many states its plant needs, and a recurrent
model's fit depends on its random start. :func:`search` therefore fits the combinations of
:data:`DEFAULT_SIZES` (or the sizes asked for) and ``seeds`` seeds
(:func:`controllers.identification.simulation.fit_candidate`) and keeps the candidate with the
lowest validation simulation RMS (training RMS when the record has no validation rows; ties
go to the smaller model, then the lower seed).

The sizes are tried in a **ladder**, one per seed: each seed's lane fits the smallest size,
then the next, and stops growing when a size does not simulate the validation rows better
than the lane's best so far by :data:`GROWTH` (a larger model costs the MPC n² per step, and
on the example air heater the 16-state candidates were both slower and worse than the
4-state ones). The lanes run in parallel worker processes; each is deterministic for its seed,
so the answer does not depend on the number of workers.

A contraction cap derived from the data (``rho_max``,
:mod:`controllers.identification.contraction`) costs a nearly linear plant nothing (the air
heater's capped candidates simulated as well as the uncapped ones, with ρ_s = 0.97 instead of
0.9994) but may cost a nonlinear one much (a saturating GRU state contracts faster than its
worst-case bound says: on the 1,000-sample Wiener heater of the tests, capped at 0.94, twice the
validation RMS). With ``loose``, each lane therefore fits its smallest size both with the cap
and without it (or with another), grows under the cap unless the other was better by more
than :data:`PREFER_CAPPED`, and the same rule picks the model kept among all: a tighter
certificate where it costs (almost) no accuracy.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from controllers.identification.record import Record
from controllers.identification.simulation import Candidate, SimOptions, fit_candidate
from controllers.workers import map_in_workers

__all__ = ["DEFAULT_SEEDS", "DEFAULT_SIZES", "GROWTH", "PREFER_CAPPED", "SearchResult",
           "candidates", "planned_steps", "search"]

#: GRU sizes tried by default.
DEFAULT_SIZES = (4, 8, 16)
#: Seeds per size tried by default.
DEFAULT_SEEDS = 2
#: A lane tries its next size only when its last one lowered the lane's best validation RMS by
#: at least this share.
GROWTH = 0.05
#: With a contraction cap and an alternative (``search``'s ``loose``), a candidate under the
#: alternative is preferred only when it simulates the validation rows better than the capped
#: one by more than this share.
PREFER_CAPPED = 0.05


@dataclass
class SearchResult:
    """The best candidate and a summary of every one (size, seed, contraction cap, score,
    best step, ν, wall time, history of evaluations), in the order they were defined; with an
    alternative cap, the best score under each and the one kept (``caps``)."""

    best: Candidate
    tried: list[dict[str, Any]] = field(default_factory=list)
    caps: dict[str, Any] = field(default_factory=dict)


def candidates(base: SimOptions, sizes: Sequence[int], seeds: int) -> list[SimOptions]:
    """Every ``(size, seed)`` combination of ``base``, the seeds ``base.seed …
    base.seed + seeds − 1``, smallest size first."""
    return [replace(base, n=int(n), seed=base.seed + k) for n in sorted(set(sizes))
            for k in range(seeds)]


def planned_steps(base: SimOptions, sizes: Sequence[int], seeds: int,
                  loose: float | None = None) -> int:
    """The most steps and iterations :func:`search` runs: every candidate's
    :attr:`SimOptions.total`, and the smallest size's once more per seed with ``loose``."""
    todo = candidates(base, sizes, seeds)
    extra = [o for o in todo if o.n == min(sizes)] if loose is not None else []
    return sum(o.total for o in todo + extra)


def _prefer_loose(loose: float, capped: float) -> bool:
    """Whether a score without the cap (``loose``) beats the capped one by
    :data:`PREFER_CAPPED`."""
    return math.isfinite(loose) and not loose >= (1.0 - PREFER_CAPPED) * capped


def _lane(args: tuple[Record, list[SimOptions], Any, float, float | None],
          progress: Callable[[int], None]) -> list[tuple[SimOptions, Candidate]]:
    """One seed's ladder of sizes (module docstring; ``growth``: :data:`GROWTH`; ``loose``:
    the alternative cap, tried at the smallest size): the candidates it fitted, in order;
    ``progress`` gets the lane's steps done, its whole plan counted once it is over."""
    record, ladder, init, growth, loose = args
    fitted: list[tuple[SimOptions, Candidate]] = []
    done = 0

    def fit(opt: SimOptions) -> Candidate:
        nonlocal done
        cand = fit_candidate(record, opt, lambda it, at=done: progress(at + it), init)
        done += opt.total
        progress(done)
        fitted.append((opt, cand))
        return cand

    cap, best = ladder[0].rho_max, fit(ladder[0]).score
    if loose is not None:
        other = fit(replace(ladder[0], rho_max=loose)).score
        if _prefer_loose(other, best):
            cap, best = loose, other
    for opt in ladder[1:]:
        score = fit(replace(opt, rho_max=cap)).score
        grew = score < best * (1.0 - growth)
        best = min(best, score)
        if not grew:
            break
    progress(sum(o.total for o in ladder) + (ladder[0].total if loose is not None else 0))
    return fitted


def search(record: Record, base: SimOptions, sizes: Sequence[int] = DEFAULT_SIZES,
           seeds: int = DEFAULT_SEEDS, workers: int = 0,
           progress: Callable[[int], None] | None = None,
           init: dict[str, Any] | None = None, growth: float = GROWTH,
           loose: float | None = None) -> SearchResult:
    """Fit the candidates of :func:`candidates` in ladders of sizes and keep the best (module
    docstring); ``tried`` lists the candidates fitted (those a ladder skipped are left out).

    Parameters
    ----------
    workers : int
        Worker processes (0: one per CPU, at most one per seed; 1: in this process).
    progress : callable, optional
        Called with the total of optimiser steps done so far, over every candidate.
    init : dict of arrays, optional
        Initial weights of every candidate (fine-tuning; ``sizes`` must be its size).
    growth : float
        The share by which a size must lower its lane's best score for the lane to try the
        next size (:data:`GROWTH`; 0: every size whenever it is better).
    loose : float, optional
        An alternative contraction cap (0: none) to ``base.rho_max``: each lane fits its
        smallest size under both and grows under the one kept (the alternative when better by
        :data:`PREFER_CAPPED`); the same rule picks the best of all.
    """
    todo = candidates(base, sizes, seeds)
    lanes = [[o for o in todo if o.seed == base.seed + k] for k in range(seeds)]
    workers = workers or min(len(lanes), os.cpu_count() or 1)
    done_steps = [0] * len(lanes)

    def tick(index: int, it: int) -> None:
        done_steps[index] = it
        if progress is not None:
            progress(sum(done_steps))

    jobs = [(record, lane, init, growth, loose) for lane in lanes]
    if workers <= 1:
        fitted = [_lane(job, lambda it, i=i: tick(i, it)) for i, job in enumerate(jobs)]
    else:
        fitted = map_in_workers(_lane, jobs, workers, tick)
    caps = [base.rho_max] + ([] if loose is None or loose == base.rho_max else [loose])
    results = sorted((r for lane in fitted for r in lane),
                     key=lambda r: (caps.index(r[0].rho_max), r[0].n, r[0].seed))
    tried = [{"n": o.n, "seed": o.seed, "rho_max": o.rho_max, "score": c.score,
              "best_step": c.best_step, "nu": c.nu, "wall_time_s": round(c.wall_time, 2),
              "history": c.history} for o, c in results]
    best = [_best([r for r in results if r[0].rho_max == c]) for c in caps]
    kept = best[0]
    if len(best) > 1 and _prefer_loose(best[1][1].score, best[0][1].score):
        kept = best[1]
    summary = {} if len(caps) < 2 else {
        "scores": {f"{c:g}": b[1].score for c, b in zip(caps, best, strict=True)},
        "kept": kept[0].rho_max}
    return SearchResult(best=kept[1], tried=tried, caps=summary)


def _best(results: list[tuple[SimOptions, Candidate]]) -> tuple[SimOptions, Candidate]:
    """The candidate with the lowest score (ties: the smaller model, then the lower seed)."""
    return min(results, key=lambda r: (r[1].score if math.isfinite(r[1].score) else math.inf,
                                       r[0].n, r[0].seed))
