"""Campaign specification files (TOML): what to run, how often, and what to draw per run.

A campaign runs one scenario many times, each run with its own seeded draws (plant parameters,
sensor perturbations, set-point sequences, initial states), once per controller *variant*, so
that controllers are compared on the same draws. Example::

    [campaign]
    name = "pump-mismatch"
    runs = 50
    seed = 3
    scenario = "scenarios/paper_steps.csv"
    controller = "robust-mpc"          # registry name or module:Class (as cosim run)
    # plant = "fmus/FourTank.fmu"      # or "model:controllers/models/fourtank_gru.json"
    # map = "...", model = "...", interface = "cs", timeout = 600, isolate = false
    # problem = "cstr.toml"            # the control problem (as --problem): the model's own,
                                       # or one for a model without; the plant is bound to it

    [controller.options]               # as cosim run --option
    offset_free = true

    [draw]                             # per-run constants at t = 0, keyed like scenario columns
    "plant.gamma_b" = { uniform = [0.37, 0.43] }
    "plant.a2" = { normal = [1.51e-4, 3e-6] }
    "sensor.h1.noise" = { uniform = [0.0, 0.003] }

    [setpoints]                        # random set-point sequences replacing the scenario's
    count = 4                          # set-points per run
    hold = 2500                        # seconds each; the run lasts count × hold
    # h1 = [0.6, 1.4]                  # range per output; default: the certified admissible
                                       # (and reachable) set-points of the robust MPC's model

    [disturbances]                     # random steps of measured disturbances (the problem's
    count = 3                          # [disturbances]) replacing the scenario's dist.* columns
    hold = 2000                        # seconds each, from the start; the last to the end
    T_in = [10.0, 30.0]                # range per disturbance (physical units)
    # ramp = true                      # reach each level at the problem's rate per sample

    [operator]                         # operator events per run (cosim.campaign.
    count = 2                          # operator_events): an input out of service, a limit
    duration = [250.0, 1000.0]         # narrowed, for a drawn while
    service = ["qa"]
    "max.h1" = [1.0, 1.4]

    [initial_state]                    # GRU-model plants ("model:...") only
    output_offset = 0.05               # start at the equilibrium of the first set-point ± this
    # observer_error = 0.02            # ‖x_0 − x̂_0‖∞ drawn up to this (default ê_o,0)

    [[variant]]                        # optional; default: one variant, the campaign's
    name = "offset-free"
    controller = "robust-mpc"
    options = { offset_free = true }

Relative paths are looked up beside the spec file first, then in the current folder. Every
error is a :class:`~cosim.core.errors.CosimError` ``file:line: message`` (exit 2).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.campaign.spec_values import Locator, file, finite, number, resolve
from cosim.core.errors import CosimError

__all__ = ["CampaignSpec", "Distribution", "DisturbanceSpec", "InitialState", "SetpointSpec",
           "Variant", "load"]

#: Most runs one campaign may ask for.
MAX_RUNS = 1_000_000
#: Distributions a ``[draw]`` entry may name, with their parameter count.
DISTRIBUTIONS = {"uniform": 2, "normal": 2, "choice": None}
_CAMPAIGN_KEYS = {"name", "runs", "seed", "scenario", "controller", "plant", "map", "model",
                  "problem", "interface", "timeout", "isolate", "step_timeout", "figures"}
_TOP_KEYS = {"campaign", "controller", "draw", "setpoints", "disturbances", "initial_state",
             "variant", "operator"}
_VARIANT_KEYS = {"name", "controller", "options", "model"}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")


@dataclass(frozen=True)
class Distribution:
    """One ``[draw]`` entry: ``kind`` in uniform/normal/choice/constant and its parameters."""

    key: str
    kind: str
    params: tuple[float, ...]


@dataclass(frozen=True)
class SetpointSpec:
    """``[setpoints]``: ``count`` set-points held ``hold`` seconds each; ``ranges`` per output
    (physical units), empty for the certified admissible range; ``first_certified``: the
    first set-point from the certified range even when ``ranges`` are given (``first =
    "certified"``: a run that starts where the FHOCP is feasible, then set-points anywhere)."""

    count: int
    hold: float
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    first_certified: bool = False


@dataclass(frozen=True)
class DisturbanceSpec:
    """``[disturbances]``: ``count`` levels of each measured disturbance, drawn uniformly in
    its range (physical units), each held ``hold`` seconds from the start (the last to the
    run's end): steps replacing the scenario's ``dist.*`` columns; ``ramp``: each level
    reached at the disturbance's rate (its problem's ``rate`` per sample) instead of in one
    step."""

    count: int
    hold: float
    ranges: dict[str, tuple[float, float]]
    ramp: bool = False


@dataclass(frozen=True)
class InitialState:
    """``[initial_state]`` of a GRU-model plant: start output offset [m] and observer error
    bound (normalised; ``None``: ``ê_o,0`` of the certificate)."""

    output_offset: float = 0.0
    observer_error: float | None = None


@dataclass(frozen=True)
class Variant:
    """A controller configuration every draw is run with."""

    name: str
    controller: str
    options: dict[str, Any]
    line: int = 0


@dataclass
class CampaignSpec:
    """A parsed campaign specification (see the module docstring)."""

    path: Path
    name: str
    runs: int
    seed: int
    scenario: Path
    controller: str
    options: dict[str, Any]
    plant: str | None = None
    map: Path | None = None
    model: Path | None = None
    problem: Path | None = None
    interface: str = "cs"
    timeout: float | None = None
    isolate: bool = False
    step_timeout: float | None = None
    figures: bool = False
    draws: tuple[Distribution, ...] = ()
    setpoints: SetpointSpec | None = None
    disturbances: DisturbanceSpec | None = None
    initial_state: InitialState | None = None
    variants: tuple[Variant, ...] = ()
    text: str = ""
    #: ``[operator]``'s events (:class:`cosim.campaign.operator_events.OperatorSpec`)
    operator: Any = None

    @property
    def model_plant(self) -> bool:
        """The plant is a GRU model file (``plant = "model:..."``)."""
        return self.plant is not None and self.plant.startswith("model:")


def _controller_file(name: str, loc: Locator, table: str, index: int = 0) -> str:
    """A controller file (``*.json``, :mod:`cosim.core.controller_file`) or a controller FMU
    (``*.fmu``) as an absolute path, checked now (found beside the spec or in the current
    folder); a controller name as is."""
    from cosim.core import controller_file

    if name.lower().endswith(".fmu"):
        path = resolve(name, loc.path.parent)
        if not path.is_file():
            raise loc.error(f"controller = {name!r}: controller FMU not found (looked beside "
                            f"the spec, {loc.path.parent}, and in the current folder)", table,
                            "controller", index)
        return str(path)
    if not controller_file.is_controller_file(name):
        return name
    path = resolve(name, loc.path.parent)
    try:
        controller_file.load(path)
    except CosimError as exc:
        raise loc.error(f"controller = {name!r}: {exc}", table, "controller", index) from None
    return str(path)


def _distribution(key: str, value: Any, loc: Locator) -> Distribution:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return Distribution(key, "constant", (float(number(value, loc, "draw", key)),))
    if not isinstance(value, dict) or len(value) != 1:
        raise loc.error(f"draw '{key}': expected a number or one of "
                        "{ uniform = [low, high] }, { normal = [mean, sd] }, "
                        "{ choice = [v1, v2, ...] }", "draw", key)
    (kind, params), = value.items()
    if kind not in DISTRIBUTIONS:
        raise loc.error(f"draw '{key}': unknown distribution '{kind}' (known: "
                        f"{', '.join(DISTRIBUTIONS)})", "draw", key)
    if not isinstance(params, list) or not params or not all(finite(v) for v in params):
        raise loc.error(f"draw '{key}': {kind} needs a list of finite numbers", "draw", key)
    want = DISTRIBUTIONS[kind]
    if want is not None and len(params) != want:
        raise loc.error(f"draw '{key}': {kind} needs {want} numbers, got {len(params)}",
                        "draw", key)
    if kind == "uniform" and params[0] > params[1]:
        raise loc.error(f"draw '{key}': uniform = [{params[0]}, {params[1]}]: the low end is "
                        "above the high end", "draw", key)
    if kind == "normal" and params[1] < 0:
        raise loc.error(f"draw '{key}': normal standard deviation {params[1]} is negative",
                        "draw", key)
    return Distribution(key, kind, tuple(float(v) for v in params))


def _draw_key(key: str, loc: Locator) -> None:
    parts = key.split(".")
    ok = ((parts[0] == "plant" and len(parts) >= 2 and all(parts[1:]))
          or (parts[0] == "sensor" and len(parts) >= 3 and all(parts[1:])
              and parts[-1] in ("bias", "noise", "uniform"))
          or (parts[0] == "ref" and len(parts) == 2 and parts[1]))
    if not ok:
        raise loc.error(f"draw '{key}': expected a scenario column name: plant.<variable>, "
                        "sensor.<output>.bias|noise|uniform or ref.<output>", "draw", key)


def _sequence(table: Any, loc: Locator, name: str, held: str, signal: str,
              keys: tuple[str, ...]) -> tuple[int, float, dict[str, tuple[float, float]]]:
    """``(count, hold, ranges)`` of a table of drawn levels (``[setpoints]``,
    ``[disturbances]``): its own keys ``keys`` besides ``count`` and ``hold`` are skipped, every
    other one is a ``signal``'s range ``[low, high]``."""
    if not isinstance(table, dict):
        raise loc.error(f"[{name}] must be a table", name)
    count = int(number(table.get("count", 1), loc, name, "count", integer=True,
                       positive=True))
    if "hold" not in table:
        raise loc.error(f"[{name}]: 'hold' (seconds each {held} is held) is missing", name)
    hold = float(number(table["hold"], loc, name, "hold", positive=True))
    ranges = {}
    for key, value in table.items():
        if key in ("count", "hold", *keys):
            continue
        if (not isinstance(value, list) or len(value) != 2
                or not all(finite(v) for v in value) or value[0] > value[1]):
            raise loc.error(f"[{name}] {key} = {value!r}: expected a range [low, high] of "
                            f"the {signal} (physical units)", name, key)
        ranges[key] = (float(value[0]), float(value[1]))
    return count, hold, ranges


def _setpoints(table: Any, loc: Locator) -> SetpointSpec:
    count, hold, ranges = _sequence(table, loc, "setpoints", "set-point", "output", ("first",))
    first = table.get("first", "drawn")
    if first not in ("drawn", "certified"):
        raise loc.error(f"[setpoints] first = {first!r}: expected \"drawn\" (like the others) "
                        "or \"certified\" (from the certified admissible range)", "setpoints",
                        "first")
    return SetpointSpec(count, hold, ranges, first == "certified")


def _disturbances(table: Any, loc: Locator) -> DisturbanceSpec:
    count, hold, ranges = _sequence(table, loc, "disturbances", "level", "disturbance",
                                    ("ramp",))
    if not ranges:
        raise loc.error("[disturbances]: no disturbance ranges (NAME = [low, high])",
                        "disturbances")
    ramp = table.get("ramp", False)
    if not isinstance(ramp, bool):
        raise loc.error(f"[disturbances] ramp = {ramp!r}: expected true (each level reached "
                        "at the disturbance's rate) or false (steps)", "disturbances", "ramp")
    return DisturbanceSpec(count, hold, ranges, ramp)


def _initial_state(table: Any, loc: Locator) -> InitialState:
    if not isinstance(table, dict):
        raise loc.error("[initial_state] must be a table", "initial_state")
    unknown = set(table) - {"output_offset", "observer_error"}
    if unknown:
        key = sorted(unknown)[0]
        raise loc.error(f"[initial_state]: unknown key '{key}' (known: output_offset, "
                        "observer_error)", "initial_state", key)
    offset = float(number(table.get("output_offset", 0.0), loc, "initial_state",
                           "output_offset", low=0.0))
    err = table.get("observer_error")
    if err is not None:
        err = float(number(err, loc, "initial_state", "observer_error", low=0.0))
    return InitialState(offset, err)


def _variants(items: Any, loc: Locator, controller: str,
              options: dict[str, Any]) -> tuple[Variant, ...]:
    if not isinstance(items, list):
        raise loc.error("variant: use [[variant]] tables", None, "variant")
    out, seen = [], set()
    for k, item in enumerate(items):
        line = loc.line("variant", None, k)
        if not isinstance(item, dict):
            raise loc.error("[[variant]] must be a table", "variant", None, k)
        unknown = set(item) - _VARIANT_KEYS
        if unknown:
            key = sorted(unknown)[0]
            raise loc.error(f"[[variant]]: unknown key '{key}' (known: "
                            f"{', '.join(sorted(_VARIANT_KEYS))})", "variant", key, k)
        name = item.get("name")
        if not isinstance(name, str) or not _NAME.match(name):
            raise loc.error(f"[[variant]] name = {name!r}: expected a name of letters, digits "
                            "and _ . + -", "variant", "name", k)
        if name in seen:
            raise loc.error(f"[[variant]]: duplicate name '{name}'", "variant", "name", k)
        seen.add(name)
        ctrl = item.get("controller", controller)
        if not isinstance(ctrl, str) or not ctrl:
            raise loc.error(f"[[variant]] controller = {ctrl!r}: expected a controller name",
                            "variant", "controller", k)
        ctrl = _controller_file(ctrl, loc, "variant", k)
        own = item.get("options", {})
        if not isinstance(own, dict):
            raise loc.error("[[variant]] options: expected a table { key = value }",
                            "variant", "options", k)
        merged = {**(options if ctrl == controller else {}), **own}
        if "model" in item:
            merged["model"] = str(file(item["model"], loc, "variant", "model", "model file"))
        out.append(Variant(name, ctrl, merged, line))
    return tuple(out)


def _read(path: Path) -> tuple[str, dict]:
    """The spec's text and its TOML document (``file:line`` errors)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CosimError(f"{path}: campaign spec not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CosimError(f"{path}: cannot read the campaign spec: {exc}") from None
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise CosimError(f"{path}:{m.group(1) if m else 1}: invalid TOML: {exc}") from None
    except RecursionError:
        raise CosimError(f"{path}:1: invalid TOML: nested too deeply") from None


def _campaign_table(doc: dict, loc: Locator) -> dict:
    """The ``[campaign]`` table, with no unknown table or key and its required keys."""
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise loc.error(f"unknown table or key '{key}' (known: "
                        f"{', '.join(sorted(_TOP_KEYS))})", None, key)
    camp = doc.get("campaign")
    if not isinstance(camp, dict):
        raise CosimError(f"{loc.path}:1: no [campaign] table")
    unknown = set(camp) - _CAMPAIGN_KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise loc.error(f"[campaign]: unknown key '{key}' (known: "
                        f"{', '.join(sorted(_CAMPAIGN_KEYS))})", "campaign", key)
    for required in ("runs", "scenario"):
        if required not in camp:
            raise loc.error(f"[campaign]: '{required}' is missing", "campaign")
    return camp


def _plant(plant: Any, loc: Locator) -> str | None:
    """``plant``: an FMU path or ``model:FILE``, the file checked to exist."""
    if plant is None:
        return None
    if not isinstance(plant, str) or not plant:
        raise loc.error("plant: expected an FMU path or model:<model file>", "campaign",
                        "plant")
    if plant.startswith("model:"):
        return "model:" + str(file(plant[len("model:"):], loc, "campaign", "plant",
                                    "model file"))
    return str(file(plant, loc, "campaign", "plant", "plant FMU"))


def _controller_options(doc: dict, loc: Locator, model: Path | None) -> dict:
    """``[controller.options]`` (with the campaign's ``model``)."""
    ctrl_table = doc.get("controller", {})
    if not isinstance(ctrl_table, dict) or set(ctrl_table) - {"options"}:
        raise loc.error("[controller]: only [controller.options] is allowed", "controller")
    options = ctrl_table.get("options", {})
    if not isinstance(options, dict):
        raise loc.error("[controller.options] must be a table", "controller.options")
    return {**options, "model": str(model)} if model is not None else options


def _draws(doc: dict, loc: Locator) -> list:
    """The ``[draw]`` table's distributions, by column."""
    draws_table = doc.get("draw", {})
    if not isinstance(draws_table, dict):
        raise loc.error("[draw] must be a table", "draw")
    draws = []
    for key, value in draws_table.items():
        if "." not in key and isinstance(value, dict) and not (
                len(value) == 1 and next(iter(value)) in DISTRIBUTIONS):
            # a dotted key without quotes ("plant.a2" written as plant.a2) nests tables
            dotted = f"{key}.{next(iter(value), '')}"
            raise loc.error(f"draw '{dotted}': quote dotted column names: \"{dotted}\" = …",
                            "draw", dotted)
        _draw_key(key, loc)
        draws.append(_distribution(key, value, loc))
    return draws


def _controller(camp: dict, loc: Locator) -> str:
    """The campaign's ``controller``: a name, a controller file or a controller FMU."""
    controller = camp.get("controller", "robust-mpc")
    if not isinstance(controller, str) or not controller:
        raise loc.error(f"controller = {controller!r}: expected a controller name",
                        "campaign", "controller")
    return _controller_file(controller, loc, "campaign")


def _execution(camp: dict, loc: Locator) -> dict[str, Any]:
    """How each run is executed: ``interface``, ``timeout``, ``step_timeout`` (it implies
    ``isolate``), ``isolate`` and ``figures``, as :class:`CampaignSpec`'s keywords."""
    interface = camp.get("interface", "cs")
    if interface not in ("cs", "me"):
        raise loc.error(f"interface = {interface!r}: expected \"cs\" or \"me\"", "campaign",
                        "interface")
    limits = {}
    for key in ("timeout", "step_timeout"):
        value = camp.get(key)
        limits[key] = (None if value is None
                       else float(number(value, loc, "campaign", key, positive=True)))
    flags = {}
    for key in ("isolate", "figures"):
        value = camp.get(key, False)
        if not isinstance(value, bool):
            raise loc.error(f"{key} = {value!r}: expected true or false", "campaign", key)
        flags[key] = value
    return {"interface": interface, **limits, "figures": flags["figures"],
            "isolate": flags["isolate"] or limits["step_timeout"] is not None}


def load(path: str | Path) -> CampaignSpec:
    """Read and check a campaign specification.

    Raises
    ------
    CosimError
        ``file:line: message`` for TOML syntax, an unknown table or key, a missing or bad
        value, a file that does not exist, an unknown distribution.
    """
    path = Path(path)
    text, doc = _read(path)
    loc = Locator(path, text)
    camp = _campaign_table(doc, loc)
    name = camp.get("name", path.stem)
    if not isinstance(name, str) or not _NAME.match(name):
        raise loc.error(f"name = {name!r}: expected a name of letters, digits and _ . + -",
                        "campaign", "name")
    runs = int(number(camp["runs"], loc, "campaign", "runs", integer=True, positive=True))
    if runs > MAX_RUNS:
        raise loc.error(f"runs = {runs}: at most {MAX_RUNS}", "campaign", "runs")
    seed = int(number(camp.get("seed", 0), loc, "campaign", "seed", integer=True, low=0))
    scenario = file(camp["scenario"], loc, "campaign", "scenario", "scenario")
    controller = _controller(camp, loc)
    plant = _plant(camp.get("plant"), loc)
    vmap, model, problem = (file(camp[key], loc, "campaign", key, kind) if key in camp
                            else None for key, kind in (("map", "variable map"),
                                                        ("model", "model file"),
                                                        ("problem", "problem file")))
    execution = _execution(camp, loc)
    options = _controller_options(doc, loc, model)
    draws = _draws(doc, loc)
    setpoints = _setpoints(doc["setpoints"], loc) if "setpoints" in doc else None
    disturbances = (_disturbances(doc["disturbances"], loc) if "disturbances" in doc
                    else None)
    initial = _initial_state(doc["initial_state"], loc) if "initial_state" in doc else None
    if initial is not None and not (isinstance(plant, str) and plant.startswith("model:")):
        raise loc.error("[initial_state] needs a GRU-model plant (plant = \"model:FILE\")",
                        "initial_state")
    variants = (_variants(doc["variant"], loc, controller, options) if "variant" in doc
                else (Variant(controller, controller, dict(options)),))
    from cosim.campaign import operator_events

    operator = (operator_events.parse(doc["operator"], loc) if "operator" in doc else None)
    return CampaignSpec(
        path=path, name=name, runs=runs, seed=seed, scenario=scenario, controller=controller,
        options=dict(options), plant=plant, map=vmap, model=model, problem=problem,
        **execution, draws=tuple(draws), setpoints=setpoints, disturbances=disturbances,
        initial_state=initial, variants=variants, text=text, operator=operator)
