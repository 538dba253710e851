"""Running a campaign on Dask: prepare, submit, collect, write, report.

The engine is Dask distributed: by default a ``LocalCluster`` on 127.0.0.1 (worker processes,
one thread each, as many as asked, default the number of cores), or an existing cluster
(``scheduler="tcp://host:port"``, started with ``dask scheduler`` and ``dask worker``, any
number of worker processes and threads each: :mod:`cosim.campaign.cluster`). No filesystem
is shared: the client sends the campaign's files once (:class:`~cosim.campaign.task.Assets`)
and each task returns its results as data; this process writes every file under the output
folder. The campaign is checked and drawn first, before the folder is touched
(:func:`cosim.campaign.plan.prepare`); then:

* ``campaign.json``: the spec, its fingerprint (spec text and input files), the plan;
* ``runs/<run>-<variant>/results.csv`` and ``summary.json`` as ``cosim run`` writes them (and
  ``traceback.txt`` when an internal error ended the run), as soon as the run comes back (a
  campaign stopped by Ctrl-C or SIGTERM keeps them, and ``resume=True`` runs only the runs
  that are missing);
* ``runs.parquet``, ``summary.json`` and ``report.png`` (:mod:`cosim.campaign.report`).

A run that fails (its FMU, its controller, a set-point it cannot reach, a timeout) is
recorded as failed with its reason; the campaign goes on.

**Lost workers and tries.** A run whose worker process dies under it (SIGKILL: preemption,
the OOM killer; a segfault in native code; the watchdog ending a run stuck past its timeout)
is *lost*, not failed: Dask reports its task as ``KilledWorker`` and the engine submits it
again. Each run says on the scheduler that it starts, before anything of it can crash
(:func:`~cosim.campaign.task.announce_start`), so the engine knows whether the run had
started when its worker died:

* lost after it started, the run used up a *try*: a run gets :data:`MAX_TRIES` tries, and
  one lost in each is recorded as failed ("the run killed its worker process in each of its
  3 tries ..."). On a worker with several threads the runs executing beside the culprit
  are lost with it and use up a try too (they had started);
* lost before it started (assigned to that worker, waiting for a thread or for the files),
  the run is submitted again without using up a try (:data:`MAX_SUBMISSIONS` submissions
  at most, whatever happened to them).

The run's ``summary.json`` records its tries (``campaign.tries``; column ``tries`` of
``runs.parquet``, 1 for a run that never lost a worker). The count is exact on the local
cluster, whose scheduler has ``distributed.scheduler.allowed-failures = 0``. An existing
cluster keeps its scheduler's ``allowed-failures`` (Dask's default 3): that scheduler
reruns a task whose worker died up to that many times before it reports ``KilledWorker``,
so there one try of the engine may cost up to ``allowed-failures + 1`` worker deaths (set it
to 0 in the cluster's configuration to make the engine's count the only one). A retried run
gives the same numbers: a run depends on its draws only, never on the worker or the try.
A cluster left without any worker ends the campaign after ``worker_timeout`` seconds, the
runs still waiting not run (:class:`~cosim.campaign.cluster.Watchdog`): it never hangs.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.campaign import cluster, report, store
from cosim.campaign.plan import Plan, prepare
from cosim.campaign.spec import CampaignSpec, load
from cosim.core import interrupts
from cosim.core.errors import CosimError
from cosim.core.run_result import COMPLETE

__all__ = ["MAX_TRIES", "CampaignResult", "default_workers", "run_campaign"]

#: Most tries of one run whose worker process dies while it runs (see the module docstring).
MAX_TRIES = 3
#: Most submissions of one run in all, tries and losses before it started together.
MAX_SUBMISSIONS = 20


@dataclass
class CampaignResult:
    """What a campaign did.

    Attributes
    ----------
    out : Path
        The output folder.
    table : pandas.DataFrame
        ``runs.parquet``: one row per run and variant on disk.
    summary : dict
        ``summary.json``.
    status : str
        ``"ok"`` (every planned run ran), ``"failed"`` (some runs failed) or
        ``"interrupted"``.
    ran : int
        Runs executed by this call (resumed ones excluded).
    """

    out: Path
    table: Any
    summary: dict
    status: str
    ran: int
    error: BaseException | None = None


def default_workers() -> int:
    """Number of local workers when none is given: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


# ---------------------------------------------------------------------------------------------
# Dask
# ---------------------------------------------------------------------------------------------

@dataclass
class ExecutionStats:
    """What :func:`_execute` measured: runs done, seconds spent writing them (client side),
    seconds the workers spent inside the runs, seconds until the cluster was ready, and
    whatever ``probe`` returned."""

    done: int = 0
    write_s: float = 0.0
    run_s: float = 0.0
    startup_s: float = 0.0
    probe: Any = None


@dataclass
class _Attempts:
    """A run's submissions so far and its counted tries (worker deaths after it started)."""

    task: dict[str, Any]
    submissions: int = 1
    lost_tries: int = 0
    lost_unstarted: int = 0


def _submit_again(at: _Attempts, started: bool, submitter: Any) -> Any:
    """Count a run lost with its worker (a try when it had started) and submit it again,
    unless it has used its tries or submissions: the new future, or None."""
    if started:
        at.lost_tries += 1
    else:
        at.lost_unstarted += 1
    if at.lost_tries < MAX_TRIES and at.submissions < MAX_SUBMISSIONS:
        at.submissions += 1
        return submitter.submit(at.task, at.submissions)
    return None


def _record(out: Path, plan: Plan, at: _Attempts, outcome: Any, error: BaseException | None,
            stats: ExecutionStats, on_done: Callable[[str], None]) -> None:
    """Write a run that came back (ok, failed, or a Dask error), Ctrl-C deferred while it is
    written. It ran once more than it was lost; one lost at its last try, as often as it
    was lost."""
    tries = at.lost_tries + (0 if cluster.lost_worker(error) else 1)
    guard = interrupts.current()
    t1 = time.perf_counter()
    with guard.deferred() if guard is not None else contextlib.nullcontext():
        status = store.write_run(
            out, plan.spec, dict(at.task, tries=tries, lost_unstarted=at.lost_unstarted),
            outcome, error)
    stats.write_s += time.perf_counter() - t1
    if outcome is not None:
        stats.run_s += outcome["wall_time_s"]
    stats.done += 1
    on_done(status)
    if guard is not None:
        guard.check()


def _execute(plan: Plan, pending: list[dict[str, Any]], out: Path, workers: int | None,
             scheduler: str | None, on_done: Callable[[str], None],
             probe: Callable[[Any], Any] | None = None, *,
             client: Any = None, worker_timeout: float | None = None) -> ExecutionStats:
    """Run ``pending`` on Dask, writing each run as it comes back; a run whose worker dies
    is submitted again (the rule: the module docstring).

    ``client``: a connected Dask client to use (else one is opened and closed here, on a
    local cluster of ``workers`` or on ``scheduler``). ``probe(client)``, when given, is
    called after the last run, before the cluster closes (the benchmark reads the workers'
    memory with it). ``worker_timeout``: seconds the cluster may have no worker before the
    runs still waiting are cancelled and :class:`~cosim.campaign.cluster.NoWorkers` raised.
    """
    from distributed import as_completed

    stats = ExecutionStats()
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(cluster.connect(workers, scheduler))
        stats.startup_s = time.perf_counter() - t0
        starts = cluster.Starts(client)
        stack.callback(starts.close)
        submitter = cluster.Submitter(client, plan)
        futures: dict[Any, _Attempts] = {}
        for task in pending:
            futures[submitter.submit(task, 1)] = _Attempts(task)
        done = as_completed(list(futures))
        watchdog = cluster.Watchdog(
            client, worker_timeout or cluster.worker_timeout_default(scheduler),
            cancel=lambda: client.cancel(list(futures)))
        stack.callback(watchdog.close)
        not_run = 0
        try:
            for future in done:
                at = futures.pop(future)
                try:
                    # blocks when the result was lost with its worker and is being recomputed
                    outcome, error = future.result(), None
                except Exception as exc:  # KilledWorker, CancelledError, a bug on the worker
                    outcome, error = None, exc
                if watchdog.reason is not None and future.status == "cancelled":
                    not_run += 1     # never ran: not written, --resume runs it
                    continue
                if cluster.lost_worker(error):
                    again = _submit_again(at, starts.started(str(future.key)), submitter)
                    if again is not None:
                        futures[again] = at
                        done.add(again)
                        continue
                _record(out, plan, at, outcome, error, stats, on_done)
            if not_run:
                raise cluster.NoWorkers(f"{watchdog.reason}: {not_run} runs not run (start "
                                        "workers, then run the campaign again with --resume)")
            if probe is not None:
                stats.probe = probe(client)
        finally:
            if futures:
                with contextlib.suppress(Exception):
                    client.cancel(list(futures), force=True)
    return stats


# ---------------------------------------------------------------------------------------------
# The whole campaign
# ---------------------------------------------------------------------------------------------

def run_campaign(spec: CampaignSpec | str | Path, out: str | Path | None = None, *,
                 workers: int | None = None, scheduler: str | None = None,
                 resume: bool = False, force: bool = False,
                 progress: bool = False,
                 worker_timeout: float | None = None) -> CampaignResult:
    """Run a campaign (the Python twin of ``cosim campaign``).

    Parameters
    ----------
    spec : CampaignSpec or path
        The specification (:func:`cosim.campaign.spec.load` reads a file).
    out : path, optional
        Output folder (default ``results/campaigns/<name>``).
    workers : int, optional
        Local Dask workers (default: the number of cores); ignored with ``scheduler``.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``).
    resume : bool
        Run only the runs that are not on disk yet (the spec must be unchanged).
    force : bool
        Start over in a folder that holds a campaign.
    progress : bool
        Show a progress bar over runs on standard error.
    worker_timeout : float, optional
        Seconds the cluster may have no worker at all before the campaign ends with the runs
        still waiting not run (``error`` a :class:`~cosim.campaign.cluster.NoWorkers`; the
        runs done are kept, ``resume`` runs the rest).
        Default :func:`cosim.campaign.cluster.worker_timeout_default`.

    Returns
    -------
    CampaignResult
        Also when interrupted (``status="interrupted"``, ``error`` the
        :class:`~cosim.core.interrupts.Interrupted`).

    Raises
    ------
    CosimError
        A bad spec or configuration, before any run.
    """
    from cosim.core.runfolder import RunFolder

    if not isinstance(spec, CampaignSpec):
        spec = load(spec)
    _check_arguments(workers, worker_timeout)
    out = Path(out) if out is not None else Path("results") / "campaigns" / spec.name
    plan = prepare(spec)
    workers = workers or default_workers()
    error: BaseException | None = None
    with contextlib.ExitStack() as stack:
        # an unreachable scheduler is bad input: found before the output folder is touched
        client = stack.enter_context(cluster.connect(None, scheduler)) if scheduler else None
        with RunFolder(out, "--out") as folder:
            pending = store.open_folder(plan, folder.path, resume, force)
            bar = _Progress(len(pending), spec.name, progress)
            ran = 0
            t0 = time.perf_counter()
            try:
                if pending:
                    ran = _execute(plan, pending, folder.path, workers, scheduler,
                                   bar.done, client=client,
                                   worker_timeout=worker_timeout).done
            except (KeyboardInterrupt, cluster.NoWorkers) as exc:
                error = exc
            finally:
                bar.close()
            table, summary = _write_report(spec, folder.path, t0, scheduler or workers)
    complete = summary.get("runs", 0) == spec.runs * len(spec.variants)
    status = ("interrupted" if error is not None or not complete
              else "failed" if summary.get("failed", 0) else "ok")
    return CampaignResult(folder.path, table, summary, status, ran, error)


def _check_arguments(workers: Any, worker_timeout: Any) -> None:
    """Reject a ``workers`` that is not a positive integer and a ``worker_timeout`` that is
    not a positive number of seconds (their command-line flags named)."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise CosimError(f"--workers {workers!r}: expected a positive integer")
    if worker_timeout is not None and not (isinstance(worker_timeout, (int, float))
                                           and math.isfinite(worker_timeout)
                                           and worker_timeout > 0):
        raise CosimError(f"--worker-timeout {worker_timeout!r}: expected a positive number "
                         "of seconds")


class _Progress:
    """The progress bar over a campaign's runs on standard error (none unless ``shown`` and
    there are runs to do), with the runs failed so far."""

    def __init__(self, total: int, name: str, shown: bool) -> None:
        self.failed = 0
        self.bar = None
        if shown and total:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="run", desc=name, file=sys.stderr,
                            dynamic_ncols=True)

    def done(self, status: str) -> None:
        """One run written, with its ``status``."""
        self.failed += status not in COMPLETE
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(failed=self.failed, refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _write_report(spec: CampaignSpec, folder: Path, t0: float, workers: Any
                  ) -> tuple[Any, dict]:
    """The campaign's tables from the runs on disk, and its ``summary.json`` (with the wall
    time since ``t0`` and the ``workers``), a signal deferred while they are written."""
    guard = interrupts.current()
    with guard.deferred() if guard is not None else contextlib.nullcontext():
        table, summary = store.build_report(spec, folder)
        summary["wall_time_s"] = round(time.perf_counter() - t0, 3)
        summary["workers"] = workers
        report.write_summary(summary, folder / "summary.json")
    return table, summary
