"""Running a campaign on Dask: prepare, submit, collect, write, report.

The engine is Dask distributed: by default a ``LocalCluster`` on 127.0.0.1 (worker processes,
one thread each, as many as asked, default the number of cores), or an existing cluster
(``scheduler="tcp://host:port"``, started with ``dask scheduler`` and ``dask worker``, any
number of worker processes and threads each: :mod:`cosim.campaign.cluster`). No filesystem
is shared: the client sends the campaign's files once (:class:`~cosim.campaign.task.Assets`)
and each task returns its results as data; this process writes every file under the output
folder:

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
import hashlib
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from cosim.campaign import cluster, report, store
from cosim.campaign.draws import DrawContext, RunDraw, draw_run
from cosim.campaign.spec import CampaignSpec, load
from cosim.campaign.task import Assets
from cosim.core import interrupts
from cosim.core.errors import CosimError
from cosim.core.run_result import COMPLETE

__all__ = ["MAX_TRIES", "CampaignResult", "default_workers", "run_campaign"]

#: Most tries of one run whose worker process dies while it runs (see the module docstring).
MAX_TRIES = 3
#: Most submissions of one run in all, tries and losses before it started together.
MAX_SUBMISSIONS = 20
#: Seconds a run may take by default: this much plus :data:`TIMEOUT_PER_STEP` per step.
TIMEOUT_BASE = 60.0
TIMEOUT_PER_STEP = 0.5


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
# Preparation (client side, before any run): everything a bad spec can get wrong fails here
# ---------------------------------------------------------------------------------------------

@dataclass
class Plan:
    """A checked campaign ready to run (:func:`prepare`): the spec, the files the workers
    get, one task per (run, variant) with its draws, the fingerprint ``--resume`` compares,
    and the run timeout [s]."""

    spec: CampaignSpec
    assets: Assets
    tasks: list[dict[str, Any]]      # one per (run, variant), draws included
    fingerprint: str
    timeout: float


def _read(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise CosimError(f"{path}: cannot read the {what}: {exc.strerror}") from None


def _plant_file(spec: CampaignSpec) -> Path:
    if spec.plant is not None and not spec.model_plant:
        return Path(spec.plant)
    from cosim.core.plants import plant_path

    return plant_path(None)


def _validate(spec: CampaignSpec, draw: RunDraw, variant_controllers: dict[str, Any],
              varmaps: dict[str, Any] | None = None) -> float:
    """Wire run 0 of every variant (as a worker will: its plant bound through
    ``varmaps[variant]``) and return the controller sample time.

    Raises :class:`CosimError` naming the spec's line for a draw key the plant or the
    scenario does not know.
    """
    from cosim.campaign.spec import _Locator
    from cosim.core import scenario as scenario_mod
    from cosim.core.master import Master

    varmaps = varmaps or {}
    sc = scenario_mod.load(spec.scenario)
    at_start = dict(draw.values)
    at_start.update({f"plant.{k}": v for k, v in draw.plant_start.items()})
    loc = _Locator(spec.path, spec.text)
    sc = sc.with_changes(at_start, list(draw.setpoints) or None, draw.stop_time,
                         list(draw.disturbances) or None)
    sample = None
    for name, ctrl in variant_controllers.items():
        if spec.model_plant:
            from cosim.adapters.gru_plant import GRUPlant

            plant: Any = GRUPlant.from_file(spec.plant or "")
        else:
            from cosim.core.fmu import FmuComponent

            plant = FmuComponent(_plant_file(spec), interface=spec.interface,
                                 varmap=varmaps.get(name))
        settable = plant.settable(True) if hasattr(plant, "settable") else set()
        measured = {s.name for s in plant.outputs}
        for key in draw.values:
            parts = key.split(".")
            if parts[0] == "plant" and key[len("plant."):] not in settable:
                raise loc.error(f"draw '{key}': the plant has no input or parameter "
                                f"'{key[len('plant.'):]}'", "draw", key)
            if parts[0] == "sensor" and ".".join(parts[1:-1]) not in measured:
                raise loc.error(f"draw '{key}': the plant has no output "
                                f"'{'.'.join(parts[1:-1])}'", "draw", key)
        try:
            Master(plant, ctrl, sc, seed=draw.seed)
        except CosimError as exc:
            raise CosimError(f"{spec.path}: variant '{name}': {exc}") from None
        sample = sample or getattr(ctrl, "sample_time", None)
    return float(sample or 1.0)


def _problem_line(spec: CampaignSpec) -> int:
    """The line of the spec's ``problem`` key (1 without one): where a default variant's
    faults of the problem are reported."""
    if spec.problem is None:
        return 1
    from cosim.campaign.spec import _Locator

    return _Locator(spec.path, spec.text).line("campaign", "problem")


def _bind(spec: CampaignSpec, name: str, line: int, ctrl: Any, problem: Any,
          user_map: Any) -> Any:
    """The variable map binding the variant's control problem (its controller's, else
    ``problem``; else the plant variables a controller FMU records) to the plant FMU
    (``user_map`` first); ``user_map`` for a GRU-model plant or a controller with none."""
    from cosim.adapters.plants import plant_varmap
    from cosim.api import run_problem, run_signals

    if spec.model_plant:
        return user_map
    bound = run_problem(ctrl, problem)
    try:
        return plant_varmap(_plant_file(spec), user_map, bound, run_signals(ctrl, bound))
    except CosimError as exc:
        raise CosimError(f"{spec.path}:{line}: variant '{name}': {exc}") from None


def prepare(spec: CampaignSpec) -> Plan:
    """Check the spec against the real plant and controllers, draw every run, pack the
    files; raises :class:`CosimError` (exit 2) before anything runs."""
    from cosim.core import registry, varmap
    from cosim.core import scenario as scenario_mod

    files: dict[str, bytes] = {"scenario.csv": _read(spec.scenario, "scenario")}
    if spec.model_plant:
        plant = ("model", "plant_model.json")
        files["plant_model.json"] = _read(Path(spec.plant[len("model:"):]),  # type: ignore[index]
                                          "plant model")
    else:
        plant = ("fmu", "plant.fmu")
        files["plant.fmu"] = _read(_plant_file(spec), "plant FMU")
    user_map = None
    if spec.map is not None:
        files["plant.map.toml"] = _read(spec.map, "variable map")
        user_map = varmap.load(spec.map)
    sc = scenario_mod.load(spec.scenario)
    ctx = DrawContext.build(spec, sc.start_time)
    draws = [draw_run(spec, i, ctx) for i in range(spec.runs)]
    controllers, variant_options, varmaps, names = {}, {}, {}, {}
    for k, v in enumerate(spec.variants):
        line = v.line or _problem_line(spec)
        names[v.name], options, local = _variant_options(spec, k, v, line, files)
        try:
            controllers[v.name] = ctrl = registry.create(names[v.name], local)
        except CosimError as exc:
            raise CosimError(f"{spec.path}:{line}: variant '{v.name}': {exc}") from None
        variant_options[v.name] = options
        varmaps[v.name] = _bind(spec, v.name, line, ctrl, local.get("problem", spec.problem),
                                user_map)
    sample = _validate(spec, draws[0], controllers, varmaps)
    duration = (draws[0].stop_time or sc.stop_time) - sc.start_time
    timeout = spec.timeout or TIMEOUT_BASE + TIMEOUT_PER_STEP * duration / sample
    assets = Assets.of(files)
    fingerprint = hashlib.sha256(spec.text.encode() + assets.digest.encode()).hexdigest()
    tasks = []
    for d in draws:
        for v in spec.variants:
            tasks.append({
                "run": d.run, "variant": v.name, "controller": names[v.name],
                "options": variant_options[v.name], "draw": asdict(d),
                "scenario": "scenario.csv", "scenario_name": str(spec.scenario),
                "plant": plant, "map": "plant.map.toml" if spec.map else None,
                "binding": _entries(varmaps[v.name]), "interface": spec.interface,
                "isolate": spec.isolate,
                "step_timeout": spec.step_timeout, "timeout": timeout,
            })
    return Plan(spec, assets, tasks, fingerprint, timeout)


def _variant_options(spec: CampaignSpec, k: int, v: Any, line: int, files: dict[str, bytes]
                     ) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """Variant ``v``'s controller name and options, a controller file read
    (:func:`cosim.core.registry.expand`), the default model and the campaign's problem
    added: ``(name, options for the tasks, options here)``; the files the options name are
    packed into ``files`` (``model_<k>.json``, ``problem_<k>.toml``, a controller FMU's
    ``path_<k>.fmu``) and named so in the
    tasks' options, so that a worker on another machine needs none of this one's files."""
    from controllers.model import DEFAULT_MODEL
    from cosim.api import with_problem
    from cosim.core import registry

    name, options = registry.expand(v.controller, v.options)
    if "model" not in options and registry.CONTROLLERS.get(name) == \
            registry.CONTROLLERS["robust-mpc"]:
        options["model"] = str(DEFAULT_MODEL)
    try:
        options = with_problem(name, options,
                               str(spec.problem) if spec.problem is not None else None)
    except CosimError as exc:
        raise CosimError(f"{spec.path}:{line}: variant '{v.name}': {exc}") from None
    local = dict(options)
    for key, what, ext in (("model", "model file", "json"), ("problem", "problem file", "toml"),
                           ("path", "controller FMU", "fmu")):
        if key == "path" and name != registry.FMU_CONTROLLER:
            continue
        if isinstance(options.get(key), str | Path):
            packed = f"{key}_{k}.{ext}"
            files[packed] = _read(Path(options[key]), what)
            options[key] = packed
    return name, options, local


def _entries(vmap: Any) -> tuple[str, tuple[tuple[Any, ...], ...]] | None:
    """A variable map as plain data for the task (its path and its entries), ``None`` for
    none: the worker rebuilds it without reading the FMU again (:mod:`cosim.campaign.task`)."""
    if vmap is None:
        return None
    return (str(vmap.path), tuple((m.signal, m.variable, m.unit, m.scale, m.offset)
                                  for m in vmap.signals.values()))


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
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise CosimError(f"--workers {workers!r}: expected a positive integer")
    if worker_timeout is not None and not (isinstance(worker_timeout, (int, float))
                                           and math.isfinite(worker_timeout)
                                           and worker_timeout > 0):
        raise CosimError(f"--worker-timeout {worker_timeout!r}: expected a positive number "
                         "of seconds")
    out = Path(out) if out is not None else Path("results") / "campaigns" / spec.name
    plan = prepare(spec)
    workers = workers or default_workers()
    error: BaseException | None = None
    with contextlib.ExitStack() as stack:
        # an unreachable scheduler is bad input: found before the output folder is touched
        client = stack.enter_context(cluster.connect(None, scheduler)) if scheduler else None
        with RunFolder(out, "--out") as folder:
            pending = store.open_folder(plan, folder.path, resume, force)
            bar = None
            if progress and pending:
                from tqdm import tqdm

                bar = tqdm(total=len(pending), unit="run", desc=spec.name, file=sys.stderr,
                           dynamic_ncols=True)
            failed_now = [0]

            def on_done(status: str) -> None:
                failed_now[0] += status not in COMPLETE
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(failed=failed_now[0], refresh=False)

            ran = 0
            t0 = time.perf_counter()
            try:
                if pending:
                    ran = _execute(plan, pending, folder.path, workers, scheduler,
                                   on_done, client=client,
                                   worker_timeout=worker_timeout).done
            except (KeyboardInterrupt, cluster.NoWorkers) as exc:
                error = exc
            finally:
                if bar is not None:
                    bar.close()
            guard = interrupts.current()
            with guard.deferred() if guard is not None else contextlib.nullcontext():
                table, summary = store.build_report(spec, folder.path)
                summary["wall_time_s"] = round(time.perf_counter() - t0, 3)
                summary["workers"] = scheduler or workers
                report.write_summary(summary, folder.path / "summary.json")
    complete = summary.get("runs", 0) == spec.runs * len(spec.variants)
    status = ("interrupted" if error is not None or not complete
              else "failed" if summary.get("failed", 0) else "ok")
    return CampaignResult(folder.path, table, summary, status, ran, error)


def _fmt(value: Any) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.3g}" if isinstance(value, float) else str(value)
