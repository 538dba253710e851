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
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Iterator
from typing import Any

from cosim import interrupts
from cosim.campaign.task import START_TOPIC
from cosim.errors import CosimError

__all__ = ["CONNECT_TIMEOUT", "LOCAL_CONFIG", "Starts", "Submitter", "connect", "lost_worker",
           "signals_ignored"]

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
    # the isolated FMU worker is a child process of the Dask worker
    "distributed.worker.daemon": False,
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
    the campaign's :class:`~cosim.campaign.engine.Plan`."""

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
