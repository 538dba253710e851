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
import multiprocessing
import os
import queue
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

from controllers.identification.record import Record
from controllers.identification.simulation import Candidate, SimOptions, fit_candidate

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


#: The progress queue of a worker process (:func:`_start_worker`).
_TICKS: Any = None


def _start_worker(ticks: Any) -> None:
    global _TICKS
    _TICKS = ticks


def _fit(args: tuple[Record, SimOptions, int, Any]) -> tuple[int, Candidate]:
    record, opt, index, init = args

    def progress(it: int) -> None:
        if _TICKS is not None:
            _TICKS.put((index, it))

    return index, fit_candidate(record, opt, progress, init)


def _in_workers(todo: list[SimOptions], record: Record, workers: int, init: Any,
                tick: Callable[[int, int], None]) -> dict[int, Candidate]:
    """The candidates fitted in ``workers`` spawned processes; on any exception (an
    interrupt) the workers are terminated before it propagates."""
    ctx = multiprocessing.get_context("spawn")
    ticks = ctx.Queue()
    stop = threading.Event()

    def pump() -> None:
        while not stop.is_set():
            try:
                tick(*ticks.get(timeout=0.2))
            except queue.Empty:
                continue
            except (EOFError, OSError, ValueError):   # the queue closed under us
                return

    reader = threading.Thread(target=pump, daemon=True)
    reader.start()
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_start_worker,
                               initargs=(ticks,))
    results: dict[int, Candidate] = {}
    try:
        for i, cand in pool.map(_fit, [(record, o, i, init) for i, o in enumerate(todo)]):
            results[i] = cand
    except BaseException:
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        pool.shutdown(wait=True)
    finally:
        stop.set()
        reader.join()
        ticks.close()
    return results


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
        results = _in_workers(todo, record, workers, init, tick)
    tried = [{"n": o.n, "seed": o.seed, "score": results[i].score,
              "best_step": results[i].best_step, "nu": results[i].nu,
              "wall_time_s": round(results[i].wall_time, 2), "history": results[i].history}
             for i, o in enumerate(todo)]
    order = sorted(range(len(todo)), key=lambda i: (
        results[i].score if math.isfinite(results[i].score) else math.inf, todo[i].n,
        todo[i].seed))
    return SearchResult(best=results[order[0]], tried=tried)
