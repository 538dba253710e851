"""One campaign run, executed on a Dask worker (or in-process): data in, data out.

Nothing here assumes a filesystem shared with the client. The client sends the campaign's
files (scenario, plant FMU, variable map, model files) once as :class:`Assets` (bytes, keyed
by a content hash); each worker process writes them once into a temporary folder of its own
and reuses them for every run. A run returns its :class:`~cosim.master.RunResult` (rows as a
numpy array) and, for a GRU-model plant under the robust MPC, what the paper's theorem
promises, measured (:func:`run_task`); the client writes the files.

Controllers are built once per worker and configuration and reused: their ``setup()``
restarts them exactly (the robust MPC rebuilds its solver), so a run gives the same numbers
on a fresh worker or on one that ran a thousand others.

A run that outlives its timeout is stopped between steps (status ``failed``, "run timeout");
one stuck inside a step (native code that never returns) is ended by a watchdog that exits
the worker process 30 s later, which the client records as a killed worker.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import math
import os
import shutil
import tempfile
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Assets", "run_task"]

#: Seconds a run may stay stuck past its timeout before the watchdog ends the worker.
WATCHDOG_GRACE = 30.0
#: Exit status of a worker ended by the watchdog.
WATCHDOG_EXIT = 70
#: Controllers kept per worker process.
CACHE_SIZE = 8

_FOLDERS: dict[str, Path] = {}
_CONTROLLERS: OrderedDict[str, Any] = OrderedDict()
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


def _controller(name: str, options: dict[str, Any]) -> Any:
    """A controller from the per-worker cache (built on first use)."""
    from cosim import registry

    key = json.dumps([name, options], sort_keys=True, default=str)
    with _LOCK:
        ctrl = _CONTROLLERS.get(key)
        if ctrl is not None:
            _CONTROLLERS.move_to_end(key)
            return ctrl
    ctrl = registry.create(name, options)
    with _LOCK:
        _CONTROLLERS[key] = ctrl
        while len(_CONTROLLERS) > CACHE_SIZE:
            _CONTROLLERS.popitem(last=False)
    return ctrl


def _in_dask_worker() -> bool:
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return False
    return True


def _plant(task: dict[str, Any], folder: Path, seed: int) -> Any:
    from cosim import varmap

    kind, name = task["plant"]
    if kind == "model":
        from controllers.model_plant import GRUPlant

        return GRUPlant.from_file(str(folder / name), seed=seed)
    vmap = varmap.load(folder / task["map"]) if task.get("map") else None
    if task.get("isolate"):
        from cosim.isolated import DEFAULT_STEP_TIMEOUT, IsolatedFmuComponent

        return IsolatedFmuComponent(folder / name, interface=task["interface"], varmap=vmap,
                                    timeout=task.get("step_timeout") or DEFAULT_STEP_TIMEOUT)
    from cosim.fmu import FmuComponent

    return FmuComponent(folder / name, interface=task["interface"], varmap=vmap)


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
        obs = self.ctrl.observer
        self.check(self.plant.x, obs.x_hat, obs.e_o)

    def summary(self) -> dict[str, float]:
        """The checks, and where the true state ended: ``‖x_N − x̄‖∞`` (normalised) and
        ``‖g(x_N) − ȳ‖∞`` (the noise-free output against the set-point, physical units)."""
        from controllers import gru

        out = {"observer_checks": self.checked, "observer_bound_violations": self.violations,
               "observer_error_max_ratio": self.worst_ratio,
               "observer_error_max_excess": self.worst_excess}
        mpc, model = getattr(self.ctrl, "mpc", None), self.plant.model
        if mpc is not None and mpc.x_bar is not None:
            x_bar = np.asarray(mpc.x_bar)
            y = model.denormalize_y(gru.output(model.params, self.plant.x))
            y_bar = model.denormalize_y(gru.output(model.params, x_bar))
            out["final_state_error"] = float(np.max(np.abs(self.plant.x - x_bar)))
            out["final_output_error"] = float(np.max(np.abs(y - y_bar)))
        return out


def run_task(task: dict[str, Any], assets: Assets) -> dict[str, Any]:
    """Run one (run, variant) of a campaign; never raises for a fault of the run.

    Parameters
    ----------
    task : dict
        ``run``, ``variant``, ``controller``, ``options`` (asset file names for model
        paths), ``draw`` (a :class:`~cosim.campaign.draws.RunDraw` as a dict), ``scenario``,
        ``plant`` (``("fmu" | "model", asset name)``), ``map``, ``interface``, ``isolate``,
        ``step_timeout``, ``timeout`` [s].
    assets : Assets

    Returns
    -------
    dict
        ``result`` (a :class:`~cosim.master.RunResult` with its rows as an array and no
        exception object), ``theorem`` (dict or ``None``), ``wall_time_s``, ``worker``.
    """
    from controllers.errors import ControllersError
    from cosim import scenario
    from cosim.errors import CosimError
    from cosim.master import Master, RunResult

    wall0 = time.perf_counter()
    folder = materialize(assets)
    draw = task["draw"]
    options = dict(task["options"])
    if "model" in options:
        options["model"] = str(folder / options["model"])
    theorem = None
    watchdog = None
    try:
        sc = scenario.load(folder / task["scenario"])
        sc.path = Path(task["scenario_name"])
        at_start = dict(draw["values"])
        at_start.update({f"plant.{k}": v for k, v in draw["plant_start"].items()})
        sc = sc.with_changes(at_start, draw["setpoints"] or None, draw["stop_time"])
        ctrl = _controller(task["controller"], options)
        if hasattr(ctrl, "initial_estimate"):
            x0 = draw["initial_estimate"]
            ctrl.initial_estimate = None if x0 is None else np.asarray(x0, dtype=float)
        plant = _plant(task, folder, draw["seed"])
        master = Master(plant, ctrl, sc, seed=draw["seed"])
        monitor = None
        if task["plant"][0] == "model" and hasattr(ctrl, "observer"):
            monitor = _TheoremMonitor(plant, ctrl)
        if _in_dask_worker():
            watchdog = threading.Timer(task["timeout"] + WATCHDOG_GRACE, os._exit,
                                       args=(WATCHDOG_EXIT,))
            watchdog.daemon = True
            watchdog.start()
        result = master.run(on_step=monitor, deadline=time.monotonic() + task["timeout"],
                            step_timeout=task.get("step_timeout"))
        if monitor is not None:
            if draw["initial_estimate"] is not None:
                # k = 0, before the first step: x_0 against x̂_0 (ê_o,0)
                monitor.check(plant.x_start, np.asarray(draw["initial_estimate"]),
                              ctrl.cert.e_o0)
            theorem = monitor.summary()
    except (CosimError, ControllersError) as exc:
        result = RunResult(columns=["time"], rows=[], status="failed", reason=str(exc))
    except Exception as exc:  # a bug: keep the campaign going, name it
        result = RunResult(columns=["time"], rows=[], status="failed",
                           reason=f"{type(exc).__name__}: {exc}")
    finally:
        if watchdog is not None:
            watchdog.cancel()
    result.error = None  # exceptions do not travel; the reason does
    rows = np.asarray(result.rows, dtype=float).reshape(len(result.rows), -1)
    result.rows = rows  # type: ignore[assignment]
    return {"result": result, "theorem": theorem,
            "wall_time_s": time.perf_counter() - wall0, "worker": os.getpid()}
