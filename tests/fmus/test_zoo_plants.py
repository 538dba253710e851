"""The zoo of the field's benchmark plants (``fmus/examples``, issue 62): each built FMU against
its published model, and each plant's scenario and campaign against its problem.

- **Transfer-function plants** (Wood-Berry, the Shell fractionator): a step on every input of
  the built FMU, sampled at Ts, equals the published first-order-plus-dead-time response
  ``K (1 - exp(-(t - theta) / tau))`` of every channel to 1e-6 of the step's largest gain:
  the papers' gains, dead times and time constants.
- **ODE plants**: the published operating point (pH 7.0 at Henson & Seborg's flows, c_B 1.117
  mol/L at Bequette's dilution rate), the steady gains, dead times and time constants their
  docstrings state (measured on step responses of the FMU), the van de Vusse's inverse
  response, the pH's gain changing twentyfold over its box.
- **Scenarios**: every set-point of ``scenario.csv`` inside its output's box and reachable:
  constant inputs inside their boxes, found on the FMU's own steady states at the scenario's
  disturbances, settle the plant there; every disturbance inside its box.
- **Campaigns and units**: ``campaign.toml`` runs the plant's scenario and problem 20 times
  with parameters of the FMU drawn, the robust MPC and the PI on the same draws; every unit of
  the problem is the FMU's, and ``fmpy validate`` finds nothing wrong with the FMU.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import fmpy
import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from controllers.problem_file import load
from tests import example_builds

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "fmus" / "examples"
ZOO = ("wood_berry", "shell_fractionator", "ph_neutralisation", "van_de_vusse",
       "slow_thermal", "air_heater")
#: The published matrices (rows: outputs; columns: the FMU's inputs), in minutes.
TRANSFER_FUNCTIONS = {
    "wood_berry": {"gain": ((12.8, -18.9, 3.8), (6.6, -19.4, 4.9)),
                   "tau": ((16.7, 21.0, 14.9), (10.9, 14.4, 13.2)),
                   "dead": ((1.0, 3.0, 8.1), (7.0, 3.0, 3.4))},
    "shell_fractionator": {"gain": ((4.05, 1.77, 5.88, 1.20, 1.44),
                                    (5.39, 5.72, 6.90, 1.52, 1.83),
                                    (4.38, 4.42, 7.20, 1.14, 1.26)),
                           "tau": ((50, 60, 50, 45, 40), (50, 60, 40, 25, 20),
                                   (33, 44, 19, 24, 32)),
                           "dead": ((27, 28, 27, 27, 27), (18, 14, 15, 15, 15),
                                    (20, 22, 0, 0, 0))}}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("zoo")
    return {name: example_builds.build(name, folder) for name in ZOO}


def _variables(fmu: Path) -> tuple[dict[str, float], list[str]]:
    """The FMU's inputs with their start values; its outputs."""
    md = fmpy.read_model_description(str(fmu))
    return ({v.name: float(v.start) for v in md.modelVariables if v.causality == "input"},
            [v.name for v in md.modelVariables if v.causality == "output"])


def step_response(fmu: Path, name: str, delta: float, ts: float, steps: int,
                  at: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """The outputs at ``k ts``, ``k = 0..steps``, with input ``name`` stepped by ``delta``
    at ``t = ts`` (the plant at rest before, at its start values and the inputs ``at``)."""
    inputs, outputs = _variables(fmu)
    inputs.update(at or {})
    table = np.zeros(2, dtype=[("time", float)] + [(k, float) for k in inputs])
    table["time"] = (0.0, ts)
    for key, value in inputs.items():
        table[key] = value
    table[name] = (inputs[name], inputs[name] + delta)
    r = fmpy.simulate_fmu(str(fmu), stop_time=steps * ts, output_interval=ts, input=table,
                          output=outputs)
    return {o: r[o] for o in outputs}


def at_rest(fmu: Path, values: dict[str, float]) -> dict[str, float]:
    """The outputs at rest with the inputs and parameters ``values`` held (the FMU settles at
    its start)."""
    inputs, outputs = _variables(fmu)
    table = np.array([(0.0, *(values.get(k, v) for k, v in inputs.items()))],
                     dtype=[("time", float)] + [(k, float) for k in inputs])
    params = {k: v for k, v in values.items() if k not in inputs}
    r = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=1.0, input=table,
                          start_values=params, output=outputs)
    return {o: float(r[o][0]) for o in outputs}


def rise_time(y: np.ndarray, ts: float, dead: float, share: float = 0.632) -> float:
    """Seconds from the step (at ``ts``) plus ``dead`` to ``share`` of the response's change."""
    change = (y - y[0]) / (y[-1] - y[0])
    t = np.arange(len(y)) * ts - ts - dead
    return float(np.interp(share, change, t))


@pytest.mark.parametrize("plant", sorted(TRANSFER_FUNCTIONS))
def test_transfer_function_plants_answer_steps_as_published(plant: str,
                                                            fmus: dict[str, Path]) -> None:
    tf = TRANSFER_FUNCTIONS[plant]
    problem = load(example_builds.problem_file(plant))
    inputs, outputs = _variables(fmus[plant])
    ts, steps, delta = problem.Ts, 120, 0.1
    for j, name in enumerate(inputs):
        y = step_response(fmus[plant], name, delta, ts, steps)
        t = np.arange(steps + 1) * ts - ts                       # since the step
        for i, out in enumerate(outputs):
            k, tau, dead = (tf[key][i][j] * f for key, f in (("gain", 1), ("tau", 60),
                                                             ("dead", 60)))
            want = np.where(t >= dead, k * delta * (1 - np.exp(-(t - dead) / tau)), 0.0)
            err = np.max(np.abs(y[out] - y[out][0] - want))
            assert err < 1e-6 * abs(k) * delta, (plant, name, out, err)


def test_ph_neutralisation_is_henson_and_seborgs(fmus: dict[str, Path]) -> None:
    """pH 7.0 at the published flows (q1 16.6, q2 0.55, q3 15.6 mL/s; the invariants Henson &
    Seborg round to -4.32e-4 and 5.28e-4 M give 7.03), a steady gain that changes twentyfold
    over the box (0.31 per mL/s at pH 6.4, 2.8 at pH 8, 0.15 at pH 10) and a response of
    about the residence time (88 s)."""
    fmu = fmus["ph_neutralisation"]
    assert at_rest(fmu, {})["pH"] == pytest.approx(7.0, abs=0.05)
    gains = {}
    for q3, want in ((14.0, 0.31), (16.5, 2.8), (20.0, 0.15)):
        y = step_response(fmu, "q3", 0.05, 15.0, 80, at={"q3": q3})["pH"]
        gains[q3] = (y[-1] - y[0]) / 0.05
        assert gains[q3] == pytest.approx(want, rel=0.1), (q3, gains[q3])
    assert max(gains.values()) / min(gains.values()) > 15.0
    y = step_response(fmu, "q3", 0.05, 15.0, 80)["pH"]
    assert 60.0 < rise_time(y, 15.0, 0.0) < 120.0


def test_van_de_vusse_is_non_minimum_phase_at_its_operating_point(fmus: dict[str, Path]
                                                                  ) -> None:
    """c_B 1.117 mol/L at D = 34.28 1/h (Bequette), the peak 1.266 mol/L at D = 77.5 1/h, the
    steady gain 0.00975 mol h/L, and a step up in D that first lowers c_B."""
    fmu = fmus["van_de_vusse"]
    assert at_rest(fmu, {})["cB"] == pytest.approx(1.117, abs=1e-3)
    peak = at_rest(fmu, {"D": 77.5})["cB"]
    assert peak == pytest.approx(1.266, abs=1e-3)
    assert at_rest(fmu, {"D": 70.0})["cB"] < peak > at_rest(fmu, {"D": 85.0})["cB"]
    y = step_response(fmu, "D", 0.2, 6.0, 100)["cB"]
    assert (y[-1] - y[0]) / 0.2 == pytest.approx(0.00975, rel=0.02)
    assert min(y[2:6] - y[0]) < -0.05 * (y[-1] - y[0])              # the inverse response


def test_slow_thermal_has_a_time_constant_of_about_fifty_samples(fmus: dict[str, Path]
                                                                ) -> None:
    """At the operating point (4 kW, Ta = 0 degC: Ti 20.2 degC) the slow mode's time constant,
    measured on the tail of a step response, is 12 h = 48 samples of 15 min (docstring: 14.0
    h at small differences, 10.7 h at 30 K), the steady gain 4.75 K/kW."""
    fmu = fmus["slow_thermal"]
    assert at_rest(fmu, {})["Ti"] == pytest.approx(20.2, abs=0.05)
    y = step_response(fmu, "P", 0.1, 900.0, 800)["Ti"]
    assert (y[-1] - y[0]) / 0.1 == pytest.approx(4.75, rel=0.02)
    t = np.arange(len(y)) * 900.0 - 900.0
    tail = (t > 20 * 3600) & (t < 50 * 3600)
    slope = np.polyfit(t[tail], np.log(y[-1] - y[tail]), 1)[0]
    assert -1.0 / slope / 900.0 == pytest.approx(48.0, rel=0.05)


def test_air_heater_is_the_issues_plant(fmus: dict[str, Path]) -> None:
    """60 s of dead time (two samples), a time constant of 7.5-8.2 min (15-16 samples of 30 s),
    1,000 W heating 20 degC inlet air to 60.4 degC; the gain falls as it heats (the wall's
    natural convection)."""
    fmu = fmus["air_heater"]
    assert at_rest(fmu, {})["T"] == pytest.approx(60.41, abs=0.01)
    y = step_response(fmu, "P", 100.0, 30.0, 200)["T"]
    assert np.all(np.abs(y[:4] - y[0]) < 1e-9) and y[4] - y[0] > 0.1   # moves 60 s after
    assert 7.5 * 60 < rise_time(y, 30.0, 60.0) < 8.2 * 60
    low = step_response(fmu, "P", 100.0, 30.0, 200, at={"P": 200.0})["T"]
    assert (low[-1] - low[0]) > 1.05 * (y[-1] - y[0])


def _reachable(fmu: Path, problem, refs: dict[str, float], dist: dict[str, float]
               ) -> dict[str, float]:
    """Constant inputs at which the plant rests at ``refs`` with the disturbances ``dist``
    (FMU variables): a root inside the box (SISO: bracketed; else Newton's steps on the
    FMU's steady states, exact for the linear plants)."""
    names = [c.variable for c in problem.inputs]
    want = np.array([refs[c.name] for c in problem.outputs])

    def rest(u: np.ndarray) -> np.ndarray:
        y = at_rest(fmu, {**dist, **dict(zip(names, u, strict=True))})
        return np.array([y[c.variable] for c in problem.outputs]) - want
    if problem.m == 1:
        c = problem.inputs[0]
        return {names[0]: brentq(lambda u: rest(np.array([u]))[0], c.min, c.max, xtol=1e-9)}
    u = np.array([(c.min + c.max) / 2 for c in problem.inputs])
    for _ in range(4):
        jac = np.column_stack([(rest(u + 1e-3 * e) - rest(u)) / 1e-3
                               for e in np.eye(len(u))])
        u = u - np.linalg.solve(jac, rest(u))
    return dict(zip(names, u, strict=True))


@pytest.mark.slow
@pytest.mark.parametrize("plant", ZOO)
def test_every_setpoint_of_the_scenario_is_reachable(plant: str, fmus: dict[str, Path]
                                                     ) -> None:
    problem = load(example_builds.problem_file(plant))
    table = pd.read_csv(EXAMPLES / plant / "scenario.csv").ffill().iloc[:-1]
    assert set(table.columns) == {"time", *(f"ref.{c.name}" for c in problem.outputs),
                                  *(f"dist.{d.name}" for d in problem.disturbances)}
    for _, row in table.iterrows():
        refs = {c.name: row[f"ref.{c.name}"] for c in problem.outputs}
        for c in problem.outputs:
            assert c.min < refs[c.name] < c.max, (plant, c.name, refs[c.name])
        dist = {d.variable: row[f"dist.{d.name}"] for d in problem.disturbances}
        for d in problem.disturbances:
            assert d.min <= dist[d.variable] <= d.max, (plant, d.name)
        u = _reachable(fmus[plant], problem, refs, dist)
        for c in problem.inputs:
            assert c.min <= u[c.variable] <= c.max, (plant, row["time"], c.name, u)
        y = at_rest(fmus[plant], {**dist, **u})
        for c in problem.outputs:
            assert y[c.variable] == pytest.approx(refs[c.name], abs=1e-6 * (c.max - c.min))


@pytest.mark.parametrize("plant", ZOO)
def test_the_campaign_runs_the_scenario_on_drawn_plants(plant: str, fmus: dict[str, Path]
                                                        ) -> None:
    spec = tomllib.loads((EXAMPLES / plant / "campaign.toml").read_text())
    camp = spec["campaign"]
    assert (camp["runs"], camp["scenario"], camp["problem"]) == (20, "scenario.csv",
                                                                 "problem.toml")
    assert camp["plant"] == f"fmu/{example_builds.fmu_name(plant)}"
    params = {v.name for v in fmpy.read_model_description(str(fmus[plant])).modelVariables
              if v.causality == "parameter"}
    drawn = {key.removeprefix("plant.") for key in spec["draw"]}
    assert drawn and drawn <= params, (drawn, params)
    variants = {v["name"]: v.get("controller", "robust-mpc") for v in spec["variant"]}
    assert variants == {"robust-mpc": "robust-mpc", "pi": "pi"}


@pytest.mark.parametrize("plant", ZOO)
def test_the_problems_units_are_the_fmus(plant: str, fmus: dict[str, Path]) -> None:
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmus[plant])) == []
    md = fmpy.read_model_description(str(fmus[plant]))
    units = {v.name: v.declaredType.unit if v.unit is None and v.declaredType else v.unit
             for v in md.modelVariables}
    defined = {u.name for u in md.unitDefinitions}
    problem = load(example_builds.problem_file(plant))
    for c in (*problem.inputs, *problem.outputs, *problem.disturbances):
        assert units[c.variable] == c.unit and c.unit in defined, (plant, c.name)
