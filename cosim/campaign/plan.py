"""A campaign checked and planned before any run: :func:`prepare` and its :class:`Plan`.

Everything a bad spec can get wrong fails here, on the client, before the output folder is
touched (a :class:`~cosim.core.errors.CosimError`, exit 2, naming the spec's line): each
variant's controller is built (a controller file read, the default model and the campaign's
problem added) and bound to the plant FMU through its control problem
(:func:`cosim.adapters.plants.plant_varmap`), run 0 of every variant is wired as a worker
will wire it (a draw the plant does not know is named), every run is drawn
(:func:`cosim.campaign.draws.draw_run`) and the files the workers need are packed once
(:class:`~cosim.campaign.task.Assets`: no filesystem is shared). The plan also holds the
fingerprint ``--resume`` compares and each run's timeout. :mod:`cosim.campaign.engine`
runs it.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from cosim.campaign.draws import DrawContext, RunDraw, draw_run
from cosim.campaign.spec import CampaignSpec
from cosim.campaign.spec_values import Locator
from cosim.campaign.task import Assets
from cosim.core.errors import CosimError

__all__ = ["TIMEOUT_BASE", "TIMEOUT_PER_STEP", "Plan", "prepare"]

#: Seconds a run may take by default: this much plus :data:`TIMEOUT_PER_STEP` per step.
TIMEOUT_BASE = 60.0
TIMEOUT_PER_STEP = 0.5


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
    from cosim.core import scenario as scenario_mod
    from cosim.core.master import Master

    varmaps = varmaps or {}
    sc = scenario_mod.load(spec.scenario)
    at_start = dict(draw.values)
    at_start.update({f"plant.{k}": v for k, v in draw.plant_start.items()})
    loc = Locator(spec.path, spec.text)
    sc = sc.with_changes(at_start, list(draw.setpoints) or None, draw.stop_time,
                         list(draw.disturbances) or None, list(draw.operator) or None)
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

    return Locator(spec.path, spec.text).line("campaign", "problem")


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
