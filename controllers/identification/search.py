"""Several candidate models (sizes and seeds) fitted side by side, the best on validation kept.

A short record does not say in advance how many states its plant needs, and a recurrent
model's fit depends on its random start. :func:`search` therefore fits every combination of
:data:`DEFAULT_SIZES` (or the sizes asked for) and ``seeds`` seeds
(:func:`controllers.identification.simulation.fit_candidate`), in parallel worker processes,
and keeps the candidate with the lowest validation simulation RMS (training RMS when the
record has no validation rows; ties go to the smaller model, then the lower seed). Each
candidate is deterministic for its seed, so the answer does not depend on the number of
workers.
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

__all__ = ["DEFAULT_SEEDS", "DEFAULT_SIZES", "SearchResult", "candidates", "search"]

#: GRU sizes tried by default.
DEFAULT_SIZES = (4, 8, 16)
#: Seeds per size tried by default.
DEFAULT_SEEDS = 2


@dataclass
class SearchResult:
    """The best candidate and a summary of every one (size, seed, score, best step, ν, wall
    time, history of evaluations), in the order they were defined."""

    best: Candidate
    tried: list[dict[str, Any]] = field(default_factory=list)


def candidates(base: SimOptions, sizes: Sequence[int], seeds: int) -> list[SimOptions]:
    """Every ``(size, seed)`` combination of ``base``, the seeds ``base.seed …
    base.seed + seeds − 1``, smallest size first."""
    return [replace(base, n=int(n), seed=base.seed + k) for n in sorted(set(sizes))
            for k in range(seeds)]


def _fit(args: tuple[Record, SimOptions, Any], progress: Callable[[int], None]) -> Candidate:
    record, opt, init = args
    return fit_candidate(record, opt, progress, init)


def search(record: Record, base: SimOptions, sizes: Sequence[int] = DEFAULT_SIZES,
           seeds: int = DEFAULT_SEEDS, workers: int = 0,
           progress: Callable[[int], None] | None = None,
           init: dict[str, Any] | None = None) -> SearchResult:
    """Fit the candidates of :func:`candidates` and keep the best (module docstring).

    Parameters
    ----------
    workers : int
        Worker processes (0: one per CPU, at most one per candidate; 1: in this process).
    progress : callable, optional
        Called with the total of optimiser steps done so far, over every candidate.
    init : dict of arrays, optional
        Initial weights of every candidate (fine-tuning; ``sizes`` must be its size).
    """
    todo = candidates(base, sizes, seeds)
    workers = workers or min(len(todo), os.cpu_count() or 1)
    done_steps = [0] * len(todo)

    def tick(index: int, it: int) -> None:
        done_steps[index] = it
        if progress is not None:
            progress(sum(done_steps))

    if workers <= 1:
        results = {i: fit_candidate(record, opt, lambda it, i=i: tick(i, it), init)
                   for i, opt in enumerate(todo)}
    else:
        results = dict(enumerate(map_in_workers(
            _fit, [(record, o, init) for o in todo], workers, tick)))
    tried = [{"n": o.n, "seed": o.seed, "score": results[i].score,
              "best_step": results[i].best_step, "nu": results[i].nu,
              "wall_time_s": round(results[i].wall_time, 2), "history": results[i].history}
             for i, o in enumerate(todo)]
    order = sorted(range(len(todo)), key=lambda i: (
        results[i].score if math.isfinite(results[i].score) else math.inf, todo[i].n,
        todo[i].seed))
    return SearchResult(best=results[order[0]], tried=tried)
