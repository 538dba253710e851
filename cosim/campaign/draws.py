"""What each run of a campaign draws: seeded, and depending on (seed, run) only.

Every ``[draw]`` key has its own random stream, ``numpy.random.default_rng([seed, run,
crc32(key)])``: adding or removing one key does not change what the others draw, and a run
draws the same values whichever worker runs it, in whatever order. Set-point sequences,
initial states and disturbance levels (steps, or ramps at their rates) have streams of
their own, and the run's noise seed (sensor noise, a GRU plant's output perturbation) is
``[seed, run]`` hashed to 32 bits.
Variants of a run share all of it: controllers are compared on the same draws.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.errors import SetpointError
from cosim.campaign.spec import CampaignSpec, Distribution
from cosim.core.errors import CosimError

__all__ = ["DrawContext", "RunDraw", "draw_run", "run_seed"]

#: Candidates tried per set-point before a certified range is declared unusable.
MAX_TRIES = 10_000


def _stream(seed: int, run: int, label: str) -> np.random.Generator:
    return np.random.default_rng([seed, run, zlib.crc32(label.encode("utf-8"))])


def run_seed(seed: int, run: int) -> int:
    """The noise seed of run ``run``: 32 bits of ``SeedSequence([seed, run])``."""
    return int(np.random.SeedSequence([seed, run]).generate_state(1, dtype=np.uint32)[0])


@dataclass(frozen=True)
class RunDraw:
    """Everything random about one run (shared by its variants).

    Attributes
    ----------
    run : int
    seed : int
        Noise seed of the run (``cosim run --seed``; a GRU plant's perturbation too).
    values : dict
        ``[draw]`` key → value, applied at the start of the run (scenario column names).
    setpoints : tuple
        ``(time, {output: value})`` set-point changes replacing the scenario's references,
        times from the scenario's start; empty when the spec has no ``[setpoints]``.
    stop_time : float or None
        The run's stop time when ``[setpoints]`` sets it.
    disturbances : tuple
        ``(time, {disturbance: value})`` changes replacing the scenario's ``dist.*`` columns;
        empty when the spec has no ``[disturbances]``.
    plant_start : dict
        GRU-model plant start parameters (``h1_start`` …, ``dx_1`` …).
    initial_estimate : list of float or None
        The observer's ``x̂_0`` (normalised) for ``[initial_state]``.
    """

    run: int
    seed: int
    values: dict[str, float] = field(default_factory=dict)
    setpoints: tuple[tuple[float, dict[str, float]], ...] = ()
    stop_time: float | None = None
    plant_start: dict[str, float] = field(default_factory=dict)
    initial_estimate: list[float] | None = None
    disturbances: tuple[tuple[float, dict[str, float]], ...] = ()
    #: ``(time, {op.<setting>: value})`` the operator's drawn events
    #: (:mod:`cosim.campaign.operator_events`), added to the scenario's
    operator: tuple[tuple[float, dict[str, float]], ...] = ()


@dataclass
class DrawContext:
    """What drawing needs beyond the spec: the scenario's times and the model certificate.

    Attributes
    ----------
    start_time : float
        The scenario's start [s].
    outputs : list of str
        Controlled outputs that set-points are drawn for.
    model : GRUModel or None
        The robust MPC's (or the GRU plant's) model: normalisation, equilibria.
    cert : Certificate or None
        Its certificate (default set-point ranges; ``ê_o,0``).
    ranges : dict
        Output → certified admissible ``(lo, hi)`` [physical units].
    rates : dict
        Measured disturbance → its largest change per sample [physical units]
        (:func:`controllers.disturbances.rates`), for ramps (``[disturbances] ramp``).
    sample_time : float
        The model's sample time [s] (the ramps' step).
    """

    start_time: float
    outputs: list[str]
    model: Any = None
    cert: Any = None
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    rates: dict[str, float] = field(default_factory=dict)
    sample_time: float = 0.0

    @classmethod
    def build(cls, spec: CampaignSpec, start_time: float) -> DrawContext:
        """Load the model and certificate when the spec needs them.

        Raises
        ------
        CosimError
            ``[setpoints]`` ranges that leave out an output the scenario sets a set-point
            for, or certified set-points (no ranges) of a model whose outputs are not the
            scenario's.
        """
        ramps = spec.disturbances is not None and spec.disturbances.ramp
        needs_model = ramps or spec.initial_state is not None or (
            spec.setpoints is not None and (not spec.setpoints.ranges
                                            or spec.setpoints.first_certified))
        scenario_refs = _scenario_refs(spec)
        if spec.setpoints is not None and spec.setpoints.ranges:
            missing = [o for o in scenario_refs if o not in spec.setpoints.ranges]
            if missing:
                raise CosimError(
                    f"{spec.path}: [setpoints]: no range for {', '.join(missing)} (the scenario "
                    f"sets ref.{missing[0]}; the drawn set-points replace all of its "
                    f"set-points): give one per output, e.g. {missing[0]} = [low, high]")
        if not needs_model:
            outputs = list(spec.setpoints.ranges) if spec.setpoints else []
            return cls(start_time, outputs)
        from controllers import laws
        from controllers.certification import certificates as certs
        from controllers.certification.output_ranges import admissible_ranges
        from controllers.model import DEFAULT_MODEL, GRUModel
        from controllers.mpc_options import MPCOptions, design_arguments

        model_path = spec.options.get("model") or spec.model or DEFAULT_MODEL
        if spec.model_plant and spec.model is None and "model" not in spec.options:
            model_path = spec.plant[len("model:"):]  # type: ignore[index]
        model = GRUModel.load(model_path)
        rates = _ramp_rates(spec, model, model_path) if ramps else {}
        if spec.setpoints is None and spec.initial_state is None:
            return cls(start_time, [], model, rates=rates, sample_time=float(model.problem.Ts))
        if spec.setpoints is not None and (not spec.setpoints.ranges
                                           or spec.setpoints.first_certified) and scenario_refs \
                and sorted(scenario_refs) != sorted(model.output_names):
            raise CosimError(
                f"{spec.path}: [setpoints]: without ranges the set-points are the certified "
                f"ones of the model {model_path} (outputs {', '.join(model.output_names)}), "
                f"but the scenario sets {', '.join(scenario_refs)}: give a range per output, "
                f"e.g. {scenario_refs[0]} = [low, high]")
        # certified for the paper's theorem as written: the same draws for every law
        reference = MPCOptions.from_mapping({"law": laws.REFERENCE})
        cert = certs.compute_certificate(model, **design_arguments(reference, model))
        ranges = {}
        for name, lo, hi in admissible_ranges(cert, model):
            if lo is None or hi is None:
                raise CosimError(f"{spec.path}: [setpoints]: the certified admissible range "
                                 f"of {name} is empty for {model_path} (give the ranges)")
            ranges[name] = (lo, hi)
        outputs = list(spec.setpoints.ranges or model.output_names) if spec.setpoints else \
            list(model.output_names)
        return cls(start_time, outputs, model, cert, ranges, rates, float(model.problem.Ts))


def _ramp_rates(spec: CampaignSpec, model: Any, model_path: Any) -> dict[str, float]:
    """Each ramped disturbance's largest change per sample [its units]: the model's problem's
    ``rate``, else its data's (:func:`controllers.disturbances.rates`)."""
    from controllers.disturbances import rates

    assert spec.disturbances is not None
    per_sample = dict(zip(model.problem.disturbance_names,
                          rates(model) * np.abs([c.scale for c in model.problem.disturbances]),
                          strict=True))
    unknown = [d for d in spec.disturbances.ranges if d not in per_sample]
    if unknown:
        raise CosimError(f"{spec.path}: [disturbances] ramp: {unknown[0]!r} is not a measured "
                         f"disturbance of the model {model_path} (its: "
                         f"{', '.join(per_sample) or 'none'}), so it has no rate")
    return per_sample


def _scenario_refs(spec: CampaignSpec) -> list[str]:
    """The outputs the campaign's scenario sets a set-point for (``ref.<output>``)."""
    from cosim.core import scenario

    try:
        return [c.target for c in scenario.load(spec.scenario).columns_of(scenario.REF)]
    except CosimError:
        return []  # reported where the scenario is read


def _sample(dist: Distribution, rng: np.random.Generator) -> float:
    if dist.kind == "constant":
        return dist.params[0]
    if dist.kind == "uniform":
        return float(rng.uniform(dist.params[0], dist.params[1]))
    if dist.kind == "normal":
        return float(rng.normal(dist.params[0], dist.params[1]))
    return float(dist.params[int(rng.integers(len(dist.params)))])


def _setpoint(spec: CampaignSpec, ctx: DrawContext, rng: np.random.Generator,
              certified: bool = False) -> dict[str, float]:
    ranges = spec.setpoints.ranges if spec.setpoints else {}  # type: ignore[union-attr]
    if ranges and not certified:
        return {o: float(rng.uniform(lo, hi)) for o, (lo, hi) in ranges.items()}
    model, cert = ctx.model, ctx.cert
    for _ in range(MAX_TRIES):
        y = {o: float(rng.uniform(*ctx.ranges[o])) for o in model.output_names}
        y_norm = model.normalize_y(np.array([y[o] for o in model.output_names]))
        if cert.failures(y_norm):
            continue
        try:
            cert.reference(y_norm, check=False)  # reachable with ‖ū‖∞ ≤ 1
        except SetpointError:
            continue
        return y
    raise CosimError(f"{spec.path}: [setpoints]: no certified, reachable set-point found in "
                     f"{MAX_TRIES} draws")


def draw_run(spec: CampaignSpec, run: int, ctx: DrawContext) -> RunDraw:
    """The draws of run ``run`` (see the module docstring)."""
    values = {d.key: _sample(d, _stream(spec.seed, run, "draw:" + d.key)) for d in spec.draws}
    setpoints: list[tuple[float, dict[str, float]]] = []
    stop = None
    if spec.setpoints is not None:
        rng = _stream(spec.seed, run, "setpoints")
        sp = spec.setpoints
        setpoints = [(ctx.start_time + j * sp.hold,
                      _setpoint(spec, ctx, rng, certified=j == 0 and sp.first_certified))
                     for j in range(sp.count)]
        stop = ctx.start_time + sp.count * sp.hold
    plant_start: dict[str, float] = {}
    x_hat0 = None
    if spec.initial_state is not None:
        plant_start, x_hat0 = _initial_state(spec, ctx, run, setpoints, values)
    steps: list[tuple[float, dict[str, float]]] = []
    if spec.disturbances is not None:
        rng = _stream(spec.seed, run, "disturbances")
        ds = spec.disturbances
        steps = [(ctx.start_time + j * ds.hold,
                  {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in ds.ranges.items()})
                 for j in range(ds.count)]
        if ds.ramp:
            steps = _ramped(steps, ctx.rates, ctx.sample_time)
    return RunDraw(run, run_seed(spec.seed, run), values, tuple(setpoints), stop, plant_start,
                   x_hat0, tuple(steps), _operator(spec, ctx, run, stop))


def _operator(spec: CampaignSpec, ctx: DrawContext, run: int, stop: float | None
              ) -> tuple[tuple[float, dict[str, float]], ...]:
    """Run ``run``'s operator events (:func:`cosim.campaign.operator_events.draw`), from the
    end of the first hold (a set-point's, else a tenth of the run) to the run's end."""
    from cosim.campaign import operator_events
    from cosim.core import scenario

    if spec.operator is None:
        return ()
    end = stop if stop is not None else scenario.load(spec.scenario).stop_time
    settle = spec.setpoints.hold if spec.setpoints is not None else 0.1 * (end - ctx.start_time)
    return tuple(operator_events.draw(spec.operator, _stream(spec.seed, run, "operator"),
                                      ctx.start_time, end, settle, _boxes(spec)))


def _boxes(spec: CampaignSpec) -> dict[str, tuple[float, float]]:
    """The engineer's box of every signal of the campaign's problem (the ``[operator]``
    limits' values at the end of their events)."""
    from cosim.adapters.problems import problem_for
    from cosim.core.errors import CosimError

    model = spec.options.get("model") or spec.model
    try:
        gru = None
        if model is not None:
            from controllers.model import GRUModel

            gru = GRUModel.load(model)
        problem = problem_for(gru, spec.problem)
    except Exception as exc:   # a model the campaign will refuse anyway: said now
        raise CosimError(f"{spec.path}: [operator]: no problem to take the limits' boxes "
                         f"from: {exc}") from None
    return problem.bounds()


def _ramped(steps: list[tuple[float, dict[str, float]]], rates: dict[str, float],
            ts: float) -> list[tuple[float, dict[str, float]]]:
    """The level steps ``steps`` as ramps: from each level's time on, every ``ts`` seconds,
    each disturbance moves towards its level by at most its rate, until it gets there or the
    next level begins (the first level is the run's start value)."""
    out = [steps[0]]
    now = dict(steps[0][1])
    for j, (t0, levels) in enumerate(steps[1:], start=1):
        end = steps[j + 1][0] if j + 1 < len(steps) else math.inf
        k = 0
        while t0 + k * ts < end and any(now[d] != v for d, v in levels.items()):
            for d, v in levels.items():
                now[d] = v if abs(v - now[d]) <= rates[d] else \
                    now[d] + math.copysign(rates[d], v - now[d])
            out.append((t0 + k * ts, dict(now)))
            k += 1
    return out


def _initial_state(spec: CampaignSpec, ctx: DrawContext, run: int,
                   setpoints: list[tuple[float, dict[str, float]]],
                   values: dict[str, float]) -> tuple[dict[str, float], list[float]]:
    """Start output near the first set-point, state offset within the observer bound."""
    from controllers.equilibrium import equilibrium_for_output

    model, init = ctx.model, spec.initial_state
    assert init is not None and model is not None
    rng = _stream(spec.seed, run, "initial_state")
    first = setpoints[0][1] if setpoints else {
        o: values.get(f"ref.{o}", float(model.y_offset[j]))
        for j, o in enumerate(model.output_names)}
    start = {o: first[o] + float(rng.uniform(-init.output_offset, init.output_offset))
             for o in model.output_names}
    bound = init.observer_error if init.observer_error is not None else ctx.cert.e_o0
    dx = rng.uniform(-bound, bound, model.n)
    x_eq, _ = equilibrium_for_output(model, model.normalize_y(
        np.array([start[o] for o in model.output_names])))
    plant = {f"{o}_start": v for o, v in start.items()}
    plant.update({f"dx_{i + 1}": float(v) for i, v in enumerate(dx)})
    return plant, [float(v) for v in x_eq]
