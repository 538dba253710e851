"""The Python API: ``cosim.run``, ``cosim.export_fmu`` and ``cosim.run_campaign``, the twins
of the commands.

    >>> import cosim
    >>> out = cosim.run("scenarios/leak_tank1.csv", controller="pi")
    >>> out.status, out.summary["kpis"]["iae"]["h1"] > 0
    ('ok', True)
    >>> out.to_pandas()[["time", "plant.h1", "ctrl.qa"]].shape
    (401, 3)

:func:`run` does what ``cosim run`` does (the command calls it): it loads the scenario, the
plant (an FMU, or a GRU model with ``"model:FILE"``) and the controller, runs the closed loop
and, when ``out`` is given, writes ``results.csv`` (streamed), ``summary.json``,
``figure.png`` and ``timings.csv`` there. Bad input raises :class:`~cosim.core.errors.CosimError`
(or a :class:`ValueError` of the numerical core) before anything runs; a run that fails or is
interrupted returns with ``status`` ``"failed"`` or ``"interrupted"``, its rows kept.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.build import TARGETS
from cosim.core.master import RunResult
from cosim.core.plants import PlantContext

__all__ = ["DEFAULT_PLANT", "RunOutput", "export_fmu", "run", "serve_plant"]

#: The project's plant FMU (FMI 2.0): ``FourTank.fmu`` beside its sources in the ``fmus``
#: package when that folder is writable (a source checkout: ``fmus/FourTank.fmu``), else in
#: the user cache (``~/.cache/gru-mpc/fmus``); built on first use (:mod:`cosim.core.build`).
DEFAULT_PLANT = TARGETS[0].fmu_path


@dataclass
class RunOutput:
    """A finished closed-loop run.

    Attributes
    ----------
    result : RunResult
        Everything recorded (columns, rows, timings), status and reason.
    summary : dict
        The ``summary.json`` document: status, KPIs, controller statistics, what was run.
    out : Path or None
        The folder the files were written to (``None`` when ``out`` was not given).
    """

    result: RunResult
    summary: dict
    out: Path | None = None
    meta: dict = field(default_factory=dict)

    @property
    def status(self) -> str:
        """``"ok"``, ``"failed"`` or ``"interrupted"``."""
        return self.result.status

    @property
    def reason(self) -> str:
        """Why the run did not finish (empty when ok)."""
        return self.result.reason

    def to_pandas(self) -> Any:
        """``results.csv`` as a DataFrame: ``time``, ``ref.h1``, ``plant.h1``, ``ctrl.qa`` …"""
        import pandas as pd

        return pd.DataFrame(self.result.rows, columns=self.result.columns)

    def timings_to_pandas(self) -> Any:
        """``timings.csv`` (wall-clock diagnostics of the controller) as a DataFrame."""
        import pandas as pd

        return pd.DataFrame(self.result.timing_rows, columns=self.result.timing_columns)


def run_signals(ctrl: Any, bound: Any) -> list[Any] | None:
    """What a controller without a problem exchanges with the plant, by the plant variables
    it records (a controller FMU of ``cosim export-fmu``); ``None`` with a problem."""
    from cosim.core.component import Capability

    if bound is not None or Capability.PLANT_SIGNALS not in ctrl.capabilities:
        return None
    return ctrl.plant_signals()


def run(scenario: str | Path, plant: str | Path | None = None,
        controller: str = "robust-mpc", map: str | Path | None = None,
        model: str | Path | None = None, options: Mapping[str, Any] | None = None, *,
        problem: Any = None, out: str | Path | None = None, interface: str = "cs",
        step: float | None = None, isolate: bool = False, step_timeout: float | None = None,
        seed: int = 0, figure: bool = True, progress: bool = False,
        on_step: Callable[[int], None] | None = None,
        on_notice: Callable[[str], None] | None = None, live: Any = None,
        mode: str | None = None, faceplate: Any = None, hmi: Any = None) -> RunOutput:
    """Run a scenario in closed loop (the Python twin of ``cosim run``).

    Parameters
    ----------
    scenario : path
        Scenario CSV file.
    plant : path or str, optional
        Plant FMU (FMI 2.0 or 3.0; default: the project's :data:`DEFAULT_PLANT`, built if
        missing), ``"model:FILE"``: the GRU model itself as the plant, or
        ``"opc.tcp://HOST:PORT"``: a live plant (or ``cosim serve-plant``), on the wall clock
        (:mod:`cosim.live`).
    controller : str
        ``"robust-mpc"``, ``"pi"`` or ``"module:Class"``.
    map : path, optional
        Variable map (TOML) of a plant whose names or units differ.
    model : path, optional
        Model file of the robust MPC (same as ``options={"model": ...}``).
    options : mapping, optional
        Controller constructor options (``{"law": "paper"}``, ``{"N": 40}``).
    problem : path or ControlProblem, optional
        The control problem (a problem file, ``--problem``): the model's own, or the problem
        of a model file that has none; the PI baseline's. Default: the controller's (the
        model's, else the four-tank's). A plant FMU is bound to it (:mod:`cosim.core.binding`:
        names through ``variable`` keys, units converted, checked before the first step).
    out : path, optional
        Folder to write the run's files into (streamed ``results.csv``, ``summary.json``,
        ``figure.png``, ``timings.csv``); nothing is written without it.
    interface : {"cs", "me"}
        FMI interface: Co-Simulation, or Model Exchange with fmpy's CVode.
    step : float, optional
        Communication step [s] (default: the controller's sample time).
    isolate : bool
        Run the plant FMU and a Python controller in worker processes too (a controller FMU
        always runs in one): a crash fails the run instead of this process, a hang is
        stopped by the step timeout (:data:`~cosim.core.isolated.DEFAULT_STEP_TIMEOUT`
        unless ``step_timeout``).
    step_timeout : float, optional
        Wall-clock limit of one plant or controller step [s] (implies ``isolate``).
    seed : int
        Seed of the measurement noise (and of a GRU plant's perturbation).
    figure : bool
        Draw ``figure.png`` (with ``out``).
    progress : bool
        Show a progress bar over the steps on standard error.
    on_step : callable, optional
        Called with the number of completed steps (progress bars).
    on_notice : callable, optional
        Called, before the run, with the controller's one-line notice when it has one (the
        robust MPC's: why it runs uncertified, :mod:`controllers.certification.grade`); a live
        run's alarms too.
    live : cosim.live.runner.LiveOptions, optional
        How a live plant is met (tags, speed, watchdog, security); default: its defaults.
    mode : {"auto", "manual"}, optional
        The operator's mode from the start (``op.mode`` in the scenario's first row, over
        its own): ``"manual"`` is the commissioning in shadow (docs: guide/operating.md).
    faceplate : cosim.live.faceplate.FaceplateOptions, optional
        Serve the controller's OPC UA faceplate while the run goes (:mod:`cosim.live.
        faceplate`: the operator's settings, set-points and predictions, writes checked
        by :class:`cosim.core.operator.OperatorDesk`).
    hmi : cosim.hmi.serving.HmiOptions or str, optional
        Serve the run's page while it runs (``"[HOST:]PORT"``, or the options with the
        users who may operate it, :mod:`cosim.hmi`); its address is handed to
        ``on_notice``. Requests from the page go through the run's operator desk (rows of
        ``operator.csv``), as the faceplate's writes and the scenario's ``op.*`` cells do.

    Returns
    -------
    RunOutput

    Raises
    ------
    CosimError
        Bad input (scenario, map, problem, FMU, options, output folder): nothing was run.
    OutputError
        ``out`` could not be written (the previous files there are intact).
    """
    from cosim.core import plants, varmap
    from cosim.core import scenario as scenario_mod
    from cosim.core.isolated import DEFAULT_STEP_TIMEOUT
    from cosim.core.master import Master

    sc = _with_mode(scenario_mod.load(scenario), mode)
    vmap = varmap.load(map) if map is not None else None
    isolate = bool(isolate or step_timeout is not None)
    limit = step_timeout if step_timeout is not None else (
        DEFAULT_STEP_TIMEOUT if isolate else None)
    opts = dict(options or {})
    if model is not None:
        opts["model"] = str(model)
    controller, opts, ctrl = _controller(controller, opts, problem, out, sc, isolate,
                                         on_notice)
    bound = run_problem(ctrl, opts.get("problem", problem))
    opened = plants.open_plant(plant, plants.PlantContext(
        sc, ctrl, bound, vmap, interface, isolate, limit, seed, step, live,
        run_signals(ctrl, bound), on_notice))
    try:
        master = Master(opened.component, ctrl, sc, step=step, seed=seed,
                        disturbances=bound.disturbance_names if bound is not None else None,
                        io=opened.io, pacer=opened.pacer)
    except BaseException:
        opened.component.terminate()
        raise
    where = opened.meta
    meta = {"scenario": str(sc.path), **where,
            "isolated": isolate, "step_timeout": limit,
            "map": str(map) if map is not None else None,
            "problem": bound.name if bound is not None else None,
            "problem_source": (bound.source or None) if bound is not None else None,
            "controller": controller, "controller_options": opts, "seed": seed}
    bar, on_step = _progress(progress, master, sc, on_step)
    served = _faceplate(faceplate, master, on_notice)
    try:
        if hmi is None:
            return _execute(master, meta, out, figure, on_step, limit)
        return _watched(master, meta, out, figure, on_step, limit, hmi, on_notice)
    except BaseException:
        if hmi is not None:
            master.plant.terminate()
            master.controller.terminate()
        raise
    finally:
        if served is not None:
            served.stop()
        if bar is not None:
            bar.close()


def _with_mode(sc: Any, mode: str | None) -> Any:
    """The scenario with ``op.mode`` set in its first row (``--mode``)."""
    from cosim.core.errors import ParameterError
    from cosim.core.operator import MODE_WORDS

    if mode is None:
        return sc
    if mode not in MODE_WORDS:
        raise ParameterError("mode", f" {mode!r}: expected {' or '.join(MODE_WORDS)}")
    return sc.with_changes(at_start={"op.mode": MODE_WORDS[mode]})


def _faceplate(options: Any, master: Any, on_notice: Callable[[str], None] | None) -> Any:
    """The faceplate served over ``master``'s operator desk (started), or ``None``."""
    if options is None:
        return None
    from cosim.core.component import Capability
    from cosim.core.errors import CosimError
    from cosim.live.faceplate import Faceplate

    if Capability.OPERATOR not in master.controller.capabilities:
        raise CosimError(f"--faceplate: controller '{master.controller.name}' takes no "
                         "operator settings")
    served = Faceplate(master.desk, master.controller, options, notice=on_notice or print)
    served.start()
    return served


def _controller(controller: str, opts: dict, problem: Any, out: str | Path | None, sc: Any,
                isolate: bool, on_notice: Callable[[str], None] | None
                ) -> tuple[str, dict, Any]:
    """The run's controller: its name and options (a controller file read, ``problem``
    added), built once ``out`` is known to be usable, checked against the scenario's
    set-points (one that refuses them: nothing runs), in a worker when ``isolate``; its
    notice handed to ``on_notice``."""
    from cosim.core import outpaths, registry
    from cosim.core.component import Capability

    controller, opts = registry.expand(controller, opts)   # a controller file read
    opts = with_problem(controller, opts, problem)
    if out is not None:
        outpaths.out_dir(out, "--out")
    ctrl = registry.create(controller, opts)
    if Capability.SETPOINTS in ctrl.capabilities:   # one that refuses them: nothing runs
        ctrl.expect_setpoints(sc.setpoints())
    if isolate and not ctrl.isolated:
        from cosim.core.isolated import IsolatedController

        ctrl = IsolatedController(ctrl, controller, opts)
    notice = ctrl.notice if Capability.NOTICE in ctrl.capabilities else None
    if notice and on_notice is not None:
        on_notice(notice)
    return controller, opts, ctrl


def _progress(shown: bool, master: Any, sc: Any, on_step: Callable[[int], None] | None
              ) -> tuple[Any, Callable[[int], None] | None]:
    """A progress bar over the run's steps on standard error when ``shown`` (else
    ``None``), and the step callback that moves it before calling ``on_step``."""
    if not shown:
        return None, on_step
    import sys

    from tqdm import tqdm

    from cosim.core.master import communication_times

    total = len(communication_times(sc.start_time, sc.stop_time, master.dt)) - 1
    bar = tqdm(total=total, unit="step", desc=sc.path.stem, file=sys.stderr,
               dynamic_ncols=True)

    def step(k: int) -> None:
        bar.update(1)
        if on_step is not None:
            on_step(k)

    return bar, step


def export_fmu(model: str | Path | None = None, out: str | Path = "Controller.fmu", *,
               fmi: int = 3, problem: str | Path | None = None,
               options: Mapping[str, Any] | None = None,
               controller: str | Path | None = None,
               scenario: str | Path | None = None) -> Path:
    """The robust MPC of ``model`` (default: the shipped one) as a controller FMU at ``out``
    (FMI ``fmi``, 2 or 3), the twin of ``cosim export-fmu`` (docs: guide/controller-fmu.md):
    the controller ``run(..., options=options)`` would build, its step compiled in C.
    ``controller``: a run's ``controller.json`` (:mod:`cosim.core.controller_file`), the
    robust MPC it describes (``options`` over its own). ``scenario``: the set-points the FMU
    will meet, checked against the certified design as ``run`` checks a scenario's (one
    outside it exports the uncertified mode, as ``run`` would switch to it); the FMU cannot
    look ahead, so without one it keeps the design's certificate.

    Raises
    ------
    CosimError
        A controller that cannot be exported (the paper's law, no compiled kernel, a
        description of another controller), no C compiler, a failed build (an existing
        ``out`` is intact).
    """
    import warnings

    from cosim.adapters.controller_export import export_fmu as export
    from cosim.core import registry
    from cosim.core.errors import CosimError

    if controller is not None:
        name, options = registry.expand(str(controller), options)
        if registry.CONTROLLERS.get(name, name) != registry.CONTROLLERS["robust-mpc"]:
            raise CosimError(f"{controller}: describes controller {name!r}; only the robust "
                             "MPC is exported")
    opts = dict(options or {})
    if model is not None:
        opts["model"] = str(model)
    if problem is not None:
        opts["problem"] = str(problem)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # no kernel: export says so
        ctrl = registry.create("robust-mpc", opts)
    if scenario is not None:
        from cosim.core.scenario import load

        ctrl.expect_setpoints(load(scenario).setpoints())
    return export(ctrl, out, fmi)


def serve_plant(plant: str | Path | None = None, problem: Any = None, *,
                map: str | Path | None = None, interface: str = "cs", **options: Any) -> dict:
    """Serve a plant FMU (default: the project's) bound to ``problem`` (default: the
    four-tank's) as an OPC UA server on the wall clock, until a signal or ``duration``: the
    twin of ``cosim serve-plant``. The FMU runs in a worker process (a crash or a step hung
    past :data:`~cosim.core.isolated.DEFAULT_STEP_TIMEOUT` stops the server, exit 1).
    ``options``: ``endpoint``, ``speed``, ``security``, ``frozen``, ``record``,
    ``duration``, ``on_notice`` (:func:`cosim.live.runner.serve`, which says what it
    returns).

    Raises
    ------
    CosimError
        Bad input (plant, problem, map, options), or the endpoint cannot be listened on.
    """
    from cosim.adapters.plants import open_fmu
    from cosim.adapters.problems import load_problem
    from cosim.core import varmap
    from cosim.core.isolated import DEFAULT_STEP_TIMEOUT
    from cosim.live.runner import serve

    bound = load_problem(problem)
    vmap = varmap.load(map) if map is not None else None
    # the FMU's native code in a worker: a crash or a hang stops the server with one line
    context = PlantContext(None, None, bound, vmap, interface, True, DEFAULT_STEP_TIMEOUT)
    return serve(open_fmu(plant, context).component, bound, **options)


def with_problem(controller: str, options: Mapping[str, Any], problem: Any) -> dict:
    """``options`` with ``problem`` (``--problem``) for a controller that takes a ``problem``
    option (the robust MPC and the PI baseline do); unchanged without one.

    Raises
    ------
    CosimError
        ``problem`` given twice, differently (``--problem`` and ``--option problem=``).
    """
    import inspect

    from cosim.core import registry
    from cosim.core.errors import CosimError

    opts = dict(options)
    if problem is None:
        return opts
    given = opts.get("problem")
    if given is not None and given != problem and str(given) != str(problem):
        raise CosimError(f"--problem {problem} and --option problem={given}: give the "
                         "problem once")
    if registry.expand(controller)[0] == registry.FMU_CONTROLLER:
        return opts   # a controller FMU's keywords are its parameters: the problem binds
    params = inspect.signature(registry.resolve(controller)).parameters   # the plant only
    if "problem" in params or any(p.kind is inspect.Parameter.VAR_KEYWORD
                                  for p in params.values()):
        opts["problem"] = problem if not isinstance(problem, Path) else str(problem)
    return opts


def run_problem(ctrl: Any, problem: Any) -> Any:
    """The control problem a run binds its plant FMU to: the controller's own (the robust
    MPC's and the PI baseline's, :func:`cosim.adapters.problems.problem_for`), else
    ``problem`` (``--problem``) loaded, else ``None`` (a controller of its own signals: the
    plant is bound through ``--map`` alone, as before problems existed)."""
    from controllers.problem import ControlProblem

    own = ctrl.problem
    if isinstance(own, ControlProblem):
        return own
    if problem is None:
        return None
    from cosim.adapters.problems import load_problem

    return load_problem(problem)


def _watched(master: Any, meta: dict, out: str | Path | None, figure: bool,
             on_step: Callable[[int], None] | None, limit: float | None, hmi: Any,
             on_notice: Callable[[str], None] | None) -> RunOutput:
    """:func:`_execute` with the run's page served (:func:`cosim.hmi.serving.watching`)."""
    from cosim.hmi.serving import HmiOptions, watching

    options = hmi if isinstance(hmi, HmiOptions) else HmiOptions.parse(hmi)
    with watching(master, meta, options, on_notice) as feed:
        return _execute(master, meta, out, figure, on_step, limit, feed)


def _execute(master: Any, meta: dict, out: Any, figure: bool,
             on_step: Callable[[int], None] | None, limit: float | None,
             feed: Any = None) -> RunOutput:
    """Run ``master`` (writing into the folder ``out`` when given) and wrap the result;
    ``feed``: the run's page (:class:`cosim.hmi.feed.Feed`), told how it ended."""
    from cosim.core import interrupts, results
    from cosim.core.errors import CosimError, SimulationFailed
    from cosim.core.runfolder import RunFolder

    if out is None:
        result = master.run(on_step=on_step, step_timeout=limit, watch=feed)
        if feed is not None:
            feed.finish(result.status, result.reason)
        _raise_load_error(result, CosimError, SimulationFailed)
        return RunOutput(result, results.summary(result, meta), None, meta)

    guard = interrupts.current()
    with RunFolder(out, "--out") as folder, \
            guard.deferred() if guard is not None else contextlib.nullcontext():
        # signals raise only inside the master's step loop; around it (set-up, writing the
        # results) they are recorded and acted on once everything is on disk
        stream = results.ResultsStream(folder.path / "results.csv")
        try:
            result = master.run(on_step=on_step, record=stream, step_timeout=limit,
                                watch=feed)
        except BaseException:
            stream.close()
            raise
        if feed is not None:
            feed.finish(result.status, result.reason)
        _raise_load_error(result, CosimError, SimulationFailed)
        described = _describe_controller(meta)
        doc = results.write(folder.path, result, meta, figure=figure, stream=stream)
        if described is not None:   # after the results: a failed write keeps them on disk
            from cosim.core import controller_file

            controller_file.write(folder.path / controller_file.FILE_NAME, described)
    return RunOutput(result, doc, folder.path, meta)


def _describe_controller(meta: dict) -> dict | None:
    """The run's controller description (:mod:`cosim.core.controller_file`), its file name
    recorded in ``meta`` (``controller_file``); ``None`` when an option is a Python object
    (the API)."""
    from cosim.core import controller_file
    from cosim.core.errors import CosimError

    meta["controller_file"] = None
    try:
        doc = controller_file.describe(meta["controller"], meta["controller_options"])
    except CosimError:
        return None
    meta["controller_file"] = controller_file.FILE_NAME
    return doc


def _raise_load_error(result: RunResult, cosim_error: type, failed: type) -> None:
    """A bad FMU found while loading it is bad input: nothing ran, nothing is written."""
    if (not result.rows and isinstance(result.error, cosim_error)
            and not isinstance(result.error, failed)):
        raise result.error
