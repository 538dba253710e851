"""One campaign run, executed on a Dask worker (or in-process): data in, data out.

Nothing here assumes a filesystem shared with the client. The client sends the campaign's
files (scenario, plant FMU, variable map, model files) once as :class:`Assets` (bytes, keyed
by a content hash); each worker process writes them once into a temporary folder of its own
and reuses them for every run. A run returns its :class:`~cosim.core.master.RunResult` (rows as a
numpy array) and, for a GRU-model plant under the robust MPC, what the paper's theorem
promises, measured (:func:`run_task`); the client writes the files.

A worker may run several runs at once (one per thread: ``dask worker --nthreads 2``), so
nothing a run uses is shared with another run: each run takes a controller of its own from
the worker's :class:`~cosim.campaign.pool.ControllerPool` (built once per configuration and
reused by later runs: ``setup()`` restarts it exactly, so a run gives the same numbers on a
fresh worker or on one that ran a thousand others) and builds its own plant, sensor and
master. What is process-wide is guarded: the asset folders (a lock here), loading an FMU
(fmpy changes the working folder: :mod:`cosim.core.fmu`), the FMU log routing
(:mod:`cosim.core.fmu_log`); signal handling and ``SIGALRM`` step timeouts are the main thread's
only (:mod:`cosim.core.interrupts`: a worker thread never installs or shares a signal guard).

A run that outlives its timeout is stopped between steps (status ``failed``, "run timeout");
one stuck inside a step (native code that never returns) is ended by a watchdog that exits
the worker process 30 s later: the only way to stop a thread stuck in native code. On a
worker with several threads the runs beside it are lost with the process too; the engine
submits every run of a dead worker again (:mod:`cosim.campaign.engine`, bounded tries).

A run never raises for a fault of its own: its reason says why, in the words ``cosim run``
uses (an unreachable first set-point, a failed certificate hypothesis, an FMU error); an
internal error (a bug) is named with the phase it happened in ("building the controller:
...", "step 37 (t = 925 s): ...") and its traceback comes back with the result, for the
client to write beside the run's files (``traceback.txt``).
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import math
import os
import shutil
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.campaign.pool import ControllerPool
from cosim.core.component import Capability
from cosim.core.run_result import COMPLETE

__all__ = ["POOL", "START_TOPIC", "Assets", "announce_start", "internal_traceback",
           "run_task"]

#: Seconds a run may stay stuck past its timeout before the watchdog ends the worker.
WATCHDOG_GRACE = 30.0
#: Exit status of a worker ended by the watchdog.
WATCHDOG_EXIT = 70

#: Topic of the event a run logs on the scheduler as it starts (:func:`announce_start`).
START_TOPIC = "cosim-run-started"
#: The idle controllers of this worker process (each run takes one of its own).
POOL = ControllerPool()

_FOLDERS: dict[str, Path] = {}
_LOCK = threading.Lock()


@dataclass(frozen=True)
class Assets:
    """The campaign's input files, by name: sent to each worker once.

    Attributes
    ----------
    files : dict of str to bytes
        File name (no folders) → content.
    digest : str
        SHA-256 of every name and content (identifies the asset set).
    """

    files: dict[str, bytes] = field(default_factory=dict)
    digest: str = ""

    @classmethod
    def of(cls, files: dict[str, bytes]) -> Assets:
        h = hashlib.sha256()
        for name in sorted(files):
            h.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
        return cls(dict(files), h.hexdigest())


def materialize(assets: Assets) -> Path:
    """The folder holding the asset files on this worker (written on first use)."""
    with _LOCK:
        folder = _FOLDERS.get(assets.digest)
        if folder is not None and folder.is_dir():
            return folder
        folder = Path(tempfile.mkdtemp(prefix=f"cosim-campaign-{assets.digest[:12]}-"))
        _remove_at_exit(folder)
        for name, data in assets.files.items():
            (folder / name).write_bytes(data)
        _FOLDERS[assets.digest] = folder
        return folder


def _remove_at_exit(folder: Path) -> None:
    """Remove ``folder`` when this process ends: at interpreter exit, and at the exit of a
    ``multiprocessing`` child (a Dask worker), which skips ``atexit``. (A worker killed by a
    crash leaves it behind, in the system's temporary folder.)"""
    from multiprocessing import util

    atexit.register(shutil.rmtree, folder, True)
    util.Finalize(None, shutil.rmtree, args=(folder, True), exitpriority=0)


def announce_start() -> None:
    """On a Dask worker: log :data:`START_TOPIC` with this task's key on the scheduler, and
    wait until it is logged (a synchronous call), before anything of the run can crash.

    A worker that dies after this point costs the run a try; one that dies before (the run
    was assigned to it and waited) does not (:mod:`cosim.campaign.engine`). Never raises.
    """
    try:
        from distributed import get_worker
        from distributed.utils import sync

        worker = get_worker()
    except (ImportError, ValueError):
        return
    with contextlib.suppress(Exception):
        sync(worker.loop, worker.scheduler.log_event, topic=START_TOPIC,
             msg={"key": str(worker.get_current_task())}, callback_timeout=30)


def _in_dask_worker() -> bool:
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return False
    return True


def _plant(task: dict[str, Any], folder: Path, seed: int) -> Any:
    """The run's plant, opened through its kind's opener (:mod:`cosim.core.plants`): the
    GRU model, or the FMU with the variable map the client bound (or the campaign's map)."""
    from cosim.core import plants, varmap
    from cosim.core.isolated import DEFAULT_STEP_TIMEOUT

    kind, name = task["plant"]
    if kind == "model":
        spec = f"model:{folder / name}"
        return plants.open_plant(spec, plants.PlantContext(None, None, seed=seed)).component
    if task.get("binding") is not None:
        # the plant bound to the control problem by the client (cosim.core.binding), map included
        path, entries = task["binding"]
        vmap = varmap.VarMap(Path(path), {m[0]: varmap.MappedSignal(*m) for m in entries})
    else:
        vmap = varmap.load(folder / task["map"]) if task.get("map") else None
    isolate = bool(task.get("isolate"))
    context = plants.PlantContext(None, None, varmap=vmap, interface=task["interface"],
                                  isolate=isolate, seed=seed,
                                  step_timeout=(task.get("step_timeout") or DEFAULT_STEP_TIMEOUT)
                                  if isolate else None)
    return plants.open_plant(folder / name, context).component


class _TheoremMonitor:
    """‖x_k − x̂_k‖∞ against ``ê_o,k`` at every step (GRU plant + robust MPC only)."""

    def __init__(self, plant: Any, ctrl: Any) -> None:
        self.plant, self.ctrl = plant, ctrl
        self.worst_ratio = 0.0
        self.worst_excess = -math.inf
        self.violations = 0
        self.checked = 0

    def check(self, x: np.ndarray, x_hat: np.ndarray | None, bound: float) -> None:
        if x_hat is None:
            return
        err = float(np.max(np.abs(x - x_hat)))
        self.checked += 1
        self.worst_excess = max(self.worst_excess, err - bound)
        self.worst_ratio = max(self.worst_ratio, err / bound if bound > 0 else math.inf)
        if err > bound * (1 + 1e-9):
            self.violations += 1

    def __call__(self, k: int) -> None:
        x_hat, bound, _ = self.ctrl.estimate()
        self.check(self.plant.x, x_hat, bound)

    def summary(self) -> dict[str, float]:
        """The checks, and where the true state ended: ``‖x_N − x̄‖∞`` (normalised) and
        ``‖g(x_N) − ȳ‖∞`` (the noise-free output against the set-point, physical units)."""
        from controllers import gru

        out = {"observer_checks": self.checked, "observer_bound_violations": self.violations,
               "observer_error_max_ratio": self.worst_ratio,
               "observer_error_max_excess": self.worst_excess}
        x_bar, model = self.ctrl.estimate()[2], self.plant.model
        if x_bar is not None:
            x_bar = np.asarray(x_bar)
            y = model.denormalize_y(gru.output(model.params, self.plant.x))
            y_bar = model.denormalize_y(gru.output(model.params, x_bar))
            out["final_state_error"] = float(np.max(np.abs(self.plant.x - x_bar)))
            out["final_output_error"] = float(np.max(np.abs(y - y_bar)))
        return out


def internal_traceback(exc: BaseException | None) -> str | None:
    """The traceback of ``exc`` when it is, or was explicitly caused by (``raise ... from``),
    an internal error: an exception that is neither a :class:`~cosim.core.errors.CosimError` nor
    a :class:`~controllers.errors.ControllersError`; else ``None`` (a fault the reason
    explains: an FMU error, an unreachable set-point)."""
    from controllers.errors import ControllersError
    from cosim.core.errors import CosimError

    seen: set[int] = set()
    cause = exc
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if not isinstance(cause, CosimError | ControllersError):
            return "".join(traceback.format_exception(exc))
        cause = cause.__cause__
    return None


def _one_line(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def _start(task: dict[str, Any], assets: Assets, run: dict[str, Any]) -> Any:
    """Everything before the first step (see :func:`run_task`); returns the master.

    ``run`` receives ``phase`` (what is being done, for the reason of an internal error),
    ``ctrl`` (with its pool ``key``) and ``plant`` as they are made.
    """
    from cosim.core import scenario
    from cosim.core.master import Master

    draw = task["draw"]
    run["phase"] = "writing the campaign's files on the worker"
    folder = materialize(assets)
    run["phase"] = "reading the scenario"
    sc = scenario.load(folder / task["scenario"])
    sc.path = Path(task["scenario_name"])
    at_start = dict(draw["values"])
    at_start.update({f"plant.{k}": v for k, v in draw["plant_start"].items()})
    sc = sc.with_changes(at_start, draw["setpoints"] or None, draw["stop_time"],
                         draw.get("disturbances") or None, draw.get("operator") or None)
    run["phase"] = "building the controller"
    options = dict(task["options"])
    from cosim.core.registry import FMU_CONTROLLER

    packed = ("model", "problem", "path") if task["controller"] == FMU_CONTROLLER else (
        "model", "problem")
    for key in packed:   # the files packed with the campaign
        if key in options:
            options[key] = str(folder / options[key])
    run["key"], ctrl = POOL.take(task["controller"], options)
    run["ctrl"] = ctrl
    if Capability.ESTIMATE in ctrl.capabilities:   # the observer's start drawn (the theorem)
        run["e_o0"] = ctrl.set_initial_estimate(draw["initial_estimate"])
    run["phase"] = "loading the plant"
    run["plant"] = plant = _plant(task, folder, draw["seed"])
    if task.get("isolate") and task["plant"][0] == "fmu" and not ctrl.isolated:
        # a Python controller's steps in a worker too (its pooled instance stays the pool's)
        from cosim.core.isolated import IsolatedController

        ctrl = IsolatedController(ctrl, task["controller"], options)
    run["phase"] = "wiring plant, controller and scenario"
    return Master(plant, ctrl, sc, seed=draw["seed"])


def run_task(task: dict[str, Any], assets: Assets) -> dict[str, Any]:
    """Run one (run, variant) of a campaign; never raises for a fault of the run.

    Parameters
    ----------
    task : dict
        ``run``, ``variant``, ``controller``, ``options`` (asset file names for model and
        problem paths), ``draw`` (a :class:`~cosim.campaign.draws.RunDraw` as a dict),
        ``scenario``, ``plant`` (``("fmu" | "model", asset name)``), ``map``, ``binding``
        (the plant's variable map bound to the control problem: its path and entries, or
        ``None``), ``interface``, ``isolate``, ``step_timeout``, ``timeout`` [s].
    assets : Assets

    Returns
    -------
    dict
        ``result`` (a :class:`~cosim.core.master.RunResult` with its rows as an array and no
        exception object), ``theorem`` (dict or ``None``), ``traceback`` (the text of an
        internal error's traceback, else ``None``), ``wall_time_s``, ``worker``.

    Notes
    -----
    The controller comes from :data:`POOL` and goes back to it only when the run ended
    ``ok``; after a failed run it is dropped (a new one is built for a later run).
    """
    from controllers.errors import ControllersError
    from cosim.core.errors import CosimError
    from cosim.core.master import RunResult

    announce_start()
    wall0 = time.perf_counter()
    draw = task["draw"]
    theorem = None
    watchdog = None
    run: dict[str, Any] = {"phase": "starting", "ctrl": None, "plant": None}
    trace = None
    try:
        master = _start(task, assets, run)
        plant, ctrl = run["plant"], run["ctrl"]
        monitor = None
        if task["plant"][0] == "model" and Capability.ESTIMATE in ctrl.capabilities:
            monitor = _TheoremMonitor(plant, ctrl)
        if _in_dask_worker():
            watchdog = threading.Timer(task["timeout"] + WATCHDOG_GRACE, os._exit,
                                       args=(WATCHDOG_EXIT,))
            watchdog.daemon = True
            watchdog.start()
        run["phase"], run["ran"] = "running", True
        result = master.run(on_step=monitor, deadline=time.monotonic() + task["timeout"],
                            step_timeout=task.get("step_timeout"))
        trace = internal_traceback(result.error)
        if monitor is not None:
            run["phase"] = "checking the theorem"
            if draw["initial_estimate"] is not None:
                # k = 0, before the first step: x_0 against x̂_0 (ê_o,0)
                monitor.check(plant.x_start, np.asarray(draw["initial_estimate"]),
                              run["e_o0"])
            theorem = monitor.summary()
    except (CosimError, ControllersError) as exc:
        # the words cosim run uses (an unreachable set-point, a bad draw for this plant)
        result = RunResult(columns=["time"], rows=[], status="failed", reason=str(exc))
        trace = internal_traceback(exc)
    except Exception as exc:  # a bug: keep the campaign going, name it and where it was
        result = RunResult(columns=["time"], rows=[], status="failed",
                           reason=f"{run['phase']}: {_one_line(exc)}")
        trace = "".join(traceback.format_exception(exc))
    finally:
        if watchdog is not None:
            watchdog.cancel()
        if run["plant"] is not None and not run.get("ran"):
            with contextlib.suppress(Exception):   # the master did not terminate it
                run["plant"].terminate()
    if run["ctrl"] is not None and result.status in COMPLETE:
        POOL.give_back(run["key"], run["ctrl"])
    result.error = None  # exceptions do not travel; the reason (and the traceback) do
    width = len(result.columns)
    rows = (np.asarray(result.rows, dtype=float).reshape(len(result.rows), -1) if result.rows
            else np.zeros((0, width)))
    result.rows = rows  # type: ignore[assignment]
    return {"result": result, "theorem": theorem, "traceback": trace,
            "wall_time_s": time.perf_counter() - wall0, "worker": os.getpid()}
