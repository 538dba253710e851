"""Jobs in spawned worker processes with their progress: what the identification search and
``cosim tune`` share.

:func:`map_in_workers` calls ``fn(job, progress)`` for every job in ``workers`` spawned
processes (spawned, not forked: no thread or lock of the caller is copied into them) and
returns the results in the jobs' order; each ``progress(value)`` a job reports reaches the
caller as ``tick(index, value)`` through a queue read by a thread of the caller. On any
exception, a Ctrl-C (:class:`KeyboardInterrupt`) included, the workers are killed before it
propagates; on Linux a worker also dies with the process that started it.
"""

from __future__ import annotations

import multiprocessing
import queue
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ["map_in_workers"]

#: The progress queue of a worker process (:func:`_start_worker`).
_TICKS: Any = None


def _start_worker(ticks: Any) -> None:
    global _TICKS
    _TICKS = ticks
    _die_with_parent()


def _die_with_parent() -> None:
    """Linux: this worker is killed when the process that started it ends, however it ends
    (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); elsewhere nothing."""
    import contextlib
    import ctypes
    import signal
    import sys

    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)


def _run(args: tuple[Callable[[Any, Callable[[Any], None]], Any], int, Any]) -> Any:
    fn, index, job = args

    def progress(value: Any) -> None:
        if _TICKS is not None:
            _TICKS.put((index, value))

    return fn(job, progress)


def map_in_workers(fn: Callable[[Any, Callable[[Any], None]], Any], jobs: Sequence[Any],
                   workers: int, tick: Callable[[int, Any], None]) -> list[Any]:
    """``[fn(job, progress) for job in jobs]`` in ``workers`` spawned processes (see the
    module docstring); ``fn`` is a module-level function (it is pickled by name)."""
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
    try:
        results = list(pool.map(_run, [(fn, i, job) for i, job in enumerate(jobs)]))
    except BaseException:
        # every worker, those the pool has registered and one it was starting when the
        # exception came (multiprocessing knows it), so that nothing outlives the call
        for proc in {*getattr(pool, "_processes", {}).values(),
                     *multiprocessing.active_children()}:
            proc.kill()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        pool.shutdown(wait=True)
    finally:
        stop.set()
        reader.join()
        ticks.close()
    return results
