"""The Dask cluster of a campaign: a new local one, or an existing one at a scheduler address.

The local cluster runs on 127.0.0.1 (every server on a free port, the dashboards too), one
worker process per run slot with one thread each, and is configured so that a run that kills
its worker costs that run one try: ``allowed-failures = 0`` (the engine counts the tries,
:mod:`cosim.campaign.engine`) and ``worker-saturation = 1.0`` (a worker is handed runs as its
thread frees). An existing cluster keeps its own configuration.

:class:`Submitter` submits the runs and the campaign's files; :class:`Starts` collects which
runs started on a worker (each run says so before anything of it can crash), so that the
engine tells a run lost with its worker after it started (a try) from one that only waited
there.

**No worker, no hang.** A cluster left without any worker (a local nanny whose restart
failed under load; an existing cluster whose workers never came, or all went) would leave the
runs waiting forever: :class:`Watchdog` restarts a local cluster's lost worker processes once
after ``worker_timeout`` seconds without a worker, and otherwise cancels the runs still
waiting and the campaign ends with :class:`NoWorkers` (exit 1); the runs already done stay on
disk, ``--resume`` runs the rest.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any

from cosim.campaign.task import START_TOPIC
from cosim.core import interrupts
from cosim.core.errors import CosimError, SimulationFailed

__all__ = ["CONNECT_TIMEOUT", "LOCAL_CONFIG", "NoWorkers", "Starts", "Submitter", "Watchdog",
           "connect", "lost_worker", "signals_ignored", "worker_timeout_default"]

#: Seconds to reach an existing scheduler before giving up (exit 2).
CONNECT_TIMEOUT = 10
#: Dask configuration of the local cluster.
LOCAL_CONFIG = {
    # a worker that dies fails its run's try at once: the engine retries it (bounded)
    "distributed.scheduler.allowed-failures": 0,
    # a worker is handed runs as its thread frees (for campaigns of more runs than twice the
    # threads: Dask queues "root-ish" tasks only); runs that wait on a worker that dies are
    # submitted again without using up a try
    "distributed.scheduler.worker-saturation": 1.0,
    "distributed.admin.tick.limit": "1h",
}


@contextlib.contextmanager
def signals_ignored() -> Iterator[None]:
    """Worker processes started in the block ignore Ctrl-C, SIGTERM and SIGHUP: the client
    handles them (and closes the cluster), so a signal to the process group does not kill
    workers half-way."""
    saved = {}
    for sig in interrupts.HANDLED:
        with contextlib.suppress(ValueError, OSError):
            saved[sig] = signal.signal(sig, signal.SIG_IGN)
    try:
        yield
    finally:
        for sig, old in saved.items():
            signal.signal(sig, old)


def _client_of(scheduler: str) -> Any:
    """A client of the scheduler at ``scheduler``; one-line :class:`CosimError` when it
    cannot be reached within :data:`CONNECT_TIMEOUT` seconds or the address is malformed."""
    from distributed import Client

    try:
        return Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise CosimError(f"--scheduler {scheduler}: cannot connect: {why}") from None


@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A Dask client on a new local cluster of ``workers`` processes, or on the cluster at
    ``scheduler``; the client (and the local cluster) are closed at the end of the block.

    Raises
    ------
    CosimError
        The scheduler cannot be reached (one line naming the address).
    """
    import dask
    from distributed import Client, LocalCluster

    loggers = [logging.getLogger(n) for n in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    cluster = None
    try:
        if scheduler:
            client = _client_of(scheduler)
        else:
            with dask.config.set(LOCAL_CONFIG), signals_ignored():
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0",
                                       worker_dashboard_address="127.0.0.1:0",
                                       silence_logs=logging.CRITICAL)
                client = Client(cluster)
        try:
            yield client
        finally:
            guard = interrupts.current()
            with guard.deferred() if guard is not None else contextlib.nullcontext():
                with contextlib.suppress(Exception):
                    client.close(timeout=10)
                if cluster is not None:
                    with contextlib.suppress(Exception):
                        cluster.close(timeout=10)
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _identity(value: Any) -> Any:
    return value


def lost_worker(error: BaseException | None) -> bool:
    """Whether a task's error says that its worker process died while it held the task."""
    return error is not None and type(error).__name__ == "KilledWorker"


class Starts:
    """The task keys whose run started on a worker (the :data:`~cosim.campaign.task.
    START_TOPIC` events, logged by each run before anything of it can crash)."""

    def __init__(self, client: Any) -> None:
        self.client = client
        self.keys: set[str] = set()
        self._lock = threading.Lock()
        client.subscribe_topic(START_TOPIC, self._on_event)

    def _on_event(self, event: tuple[float, Any]) -> None:
        msg = event[1]
        if isinstance(msg, dict):
            with self._lock:
                self.keys.add(str(msg.get("key")))

    def started(self, key: str) -> bool:
        """Whether the run of task ``key`` had started (the events the scheduler still
        holds are read when the subscription has not delivered it)."""
        with self._lock:
            if key in self.keys:
                return True
        with contextlib.suppress(Exception):
            for _, msg in self.client.get_events(START_TOPIC):
                if isinstance(msg, dict) and msg.get("key") == key:
                    return True
        return False

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.unsubscribe_topic(START_TOPIC)


class Submitter:
    """Submits runs (and the campaign's files they depend on) to a Dask client; ``plan`` is
    the campaign's :class:`~cosim.campaign.plan.Plan`."""

    def __init__(self, client: Any, plan: Any) -> None:
        self.client, self.plan = client, plan
        self.assets: Any = None
        self._assets_tries = 0

    def _files(self) -> Any:
        # a task returning the files, not scattered data: the scheduler keeps its definition,
        # so the files are recomputed if every worker holding them dies (a crashing plant);
        # submitted anew if that task itself was lost with its worker
        if self.assets is None or self.assets.status in ("error", "cancelled"):
            self._assets_tries += 1
            digest = self.plan.assets.digest
            self.assets = self.client.submit(
                _identity, self.plan.assets, pure=False,
                key=f"cosim-assets-{digest}-{self._assets_tries}")
        return self.assets

    def submit(self, task: dict[str, Any], submission: int) -> Any:
        """Submit one run; ``submission`` 1, 2, ... (part of the task's key)."""
        key = f"cosim-{self.plan.fingerprint[:10]}-{task['run']}-{task['variant']}"
        if submission > 1:
            key += f"-s{submission}"
        from cosim.campaign.task import run_task

        return self.client.submit(run_task, task, self._files(), key=key, pure=False)


#: Seconds without any worker before the runs still waiting fail: on a local cluster (its
#: nannies restart a dead worker within seconds; one that could not is restarted once), on an
#: existing cluster (its workers may wait in a batch queue).
LOCAL_WORKER_TIMEOUT, CLUSTER_WORKER_TIMEOUT = 120.0, 600.0


def worker_timeout_default(scheduler: str | None) -> float:
    """Seconds a campaign waits without any worker: :data:`LOCAL_WORKER_TIMEOUT` on a local
    cluster, :data:`CLUSTER_WORKER_TIMEOUT` on an existing one (``scheduler`` given)."""
    return CLUSTER_WORKER_TIMEOUT if scheduler else LOCAL_WORKER_TIMEOUT


class NoWorkers(SimulationFailed):
    """The cluster had no worker for the campaign's whole worker timeout: the runs still
    waiting were not run (``--resume`` runs them once workers are back); exit 1."""


class Watchdog:
    """Ends a campaign that has no worker to run on, instead of waiting forever.

    A thread asks the scheduler every ``poll`` seconds how many workers it has. After
    ``timeout`` seconds without any, on a local cluster it restarts the worker processes its
    nannies lost (a nanny whose restart failed keeps no worker: Dask logs it and waits), and
    if that brings none back within another ``timeout``, or at once on an existing cluster,
    it records why in :attr:`reason` and cancels the runs still waiting (``cancel``).

    Parameters
    ----------
    client : distributed.Client
    timeout : float
        Seconds without a worker before acting.
    cancel : callable
        Cancels the runs still waiting (called from the watchdog's thread).
    poll : float
        Seconds between two looks at the scheduler.
    """

    def __init__(self, client: Any, timeout: float, cancel: Any, poll: float = 2.0) -> None:
        self.client, self.timeout, self.cancel, self.poll = client, timeout, cancel, poll
        self.reason: str | None = None
        self.revived = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="cosim-watchdog",
                                        daemon=True)
        self._thread.start()

    def _workers(self) -> int:
        try:
            return len(self.client.scheduler_info(n_workers=-1).get("workers", {}))
        except TypeError:  # distributed without the n_workers argument
            return len(self.client.scheduler_info().get("workers", {}))
        except Exception:
            return -1  # the scheduler did not answer: not evidence of no workers

    def _revive(self) -> bool:
        """Restart the worker process of each nanny of a local cluster that has none."""
        local = getattr(self.client, "cluster", None)
        nannies = getattr(local, "workers", None)
        if not isinstance(nannies, dict):
            return False
        for nanny in list(nannies.values()):
            process = getattr(nanny, "process", None)
            alive = process is not None and getattr(process, "process", None) is not None \
                and process.process.is_alive()
            if not alive and hasattr(nanny, "instantiate"):
                with contextlib.suppress(Exception):
                    local.sync(nanny.instantiate)
                    self.revived += 1
        return self.revived > 0

    def _watch(self) -> None:
        since = time.monotonic()
        tried_revive = False
        while not self._stop.wait(self.poll):
            if self._workers() != 0:
                since = time.monotonic()
                continue
            if time.monotonic() - since < self.timeout:
                continue
            if not tried_revive:
                tried_revive = True
                if self._revive():
                    since = time.monotonic()
                    continue
            self.reason = f"no Dask worker for {self.timeout:g} s"
            for _ in range(3):  # the engine may be adding a resubmitted run meanwhile
                try:
                    self.cancel()
                    break
                except Exception:
                    time.sleep(0.1)
            return

    def close(self) -> None:
        """Stop watching."""
        self._stop.set()
        self._thread.join(timeout=self.poll + 5)
