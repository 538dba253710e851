"""A run on plants that are not the four tanks (m = 1, p = 1; m = 3, p = 2; m = 2, p = 3):
scenario columns, ``summary.json`` KPIs and the figure keyed by the problem's own signals."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.core import plots, results
from cosim.core.errors import CosimError
from cosim.core.master import Master
from cosim.core.scenario import load
from tests.cosim.other_plants import (
    HEATER,
    MIXER,
    TRIPLE,
    FirstOrderPlant,
    HeaterController,
    MixerController,
    TripleController,
    keep_figures,
)

HEATER_SCENARIO = ("time,ref.temp,plant.q_loss,sensor.temp.bias,sensor.temp.noise\n"
                   "0,320,0,0,0.1\n500,330,,0.5,\n1000,,0.2,,\n2000,,,,\n")
MIXER_SCENARIO = ("time,ref.T,ref.conc,plant.T_in,sensor.conc.noise\n"
                  "0,40,0.3,0,0.01\n500,85,0.5,20,\n1500,,,,\n")


def run(tmp_path: Path, problem: Any, controller: Any, text: str,
        monkeypatch: pytest.MonkeyPatch) -> tuple[Any, dict, list[Any]]:
    """Run the scenario ``text`` on the problem's plant; write the run folder; return the
    result, the summary.json on disk and the figure's axes."""
    path = tmp_path / "sc.csv"
    path.write_text(text)
    result = Master(FirstOrderPlant(problem), controller, load(path), seed=3).run()
    assert result.status == "ok", result.reason
    figures = keep_figures(monkeypatch)
    results.write(tmp_path / "out", result, {"scenario": "sc.csv"})
    doc = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert len(figures) == 1
    return result, doc, figures[0].axes


def column(result: Any, name: str) -> np.ndarray:
    return np.asarray(result.rows)[:, result.columns.index(name)]


def test_m1_p1_a_heater(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    result, doc, axes = run(tmp_path, HEATER, HeaterController(), HEATER_SCENARIO,
                            monkeypatch)
    assert result.columns[:7] == ["time", "ref.temp", "plant.q_loss", "plant.temp",
                                  "sensor.temp", "plant.power", "ctrl.power"]
    assert doc["signals"] == {"outputs": {"temp": {"unit": "K", "min": 290.0, "max": 350.0}},
                              "inputs": {"power": {"unit": "kW", "min": 0.0, "max": 5.0}}}
    k = doc["kpis"]
    for kpi in ("iae", "final_error", "worst_offset"):
        assert list(k[kpi]) == ["temp"], kpi
    assert list(k["tv"]) == ["power"] and set(k["violations"]) == {"temp", "power"}
    # the controller tracks what it measures: the true value is off by the sensor's bias
    assert k["final_error"]["temp"] == pytest.approx(0.5, abs=0.15)
    assert k["worst_offset"]["temp"] == pytest.approx(
        max(abs(s["offset"]["temp"]) for s in k["setpoints"]))
    assert k["tv"]["power"] == pytest.approx(np.abs(np.diff(column(result, "ctrl.power"))).sum())
    assert k["tv"]["power"] == k["control_effort"]["power"]["total_variation"]
    text = (tmp_path / "out" / "summary.json").read_text()
    assert not any(name in text for name in ("h1", "h2", "qa", "qb"))
    # one panel per signal, labelled with the problem's units
    assert [ax.get_ylabel() for ax in axes] == ["temp [K]", "power [kW]"]


def test_m3_p2_a_mixer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    result, doc, axes = run(tmp_path, MIXER, MixerController(), MIXER_SCENARIO, monkeypatch)
    k = doc["kpis"]
    assert list(k["iae"]) == ["T", "conc"] and list(k["tv"]) == ["F_hot", "F_cold", "F_acid"]
    assert list(doc["signals"]["outputs"]) == ["T", "conc"]
    assert doc["signals"]["inputs"]["F_acid"] == {"unit": "mL/min", "min": 0.0, "max": 50.0}
    # a set-point above the box (85 degC > 80 degC) is a violation of T, measured on the plant
    T = column(result, "plant.T")
    assert k["violations"]["T"] == {"max": pytest.approx(float(np.max(T - 80.0))),
                                    "count": int(np.count_nonzero(T > 80.0))}
    assert k["violations"]["T"]["count"] > 0 and k["violations"]["conc"]["count"] == 0
    assert [ax.get_ylabel() for ax in axes] == ["T [degC]", "conc [mol/L]", "F_hot [L/min]",
                                                "F_cold [L/min]", "F_acid [mL/min]"]
    # the outputs' boxes are drawn (the region outside shaded), the inputs' too
    assert all(len(ax.patches) == 2 for ax in axes)


def test_m2_p3_a_dimensionless_output(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = "time,ref.level,ref.temp,ref.pH\n0,1,320,7\n600,,,\n"
    _, doc, axes = run(tmp_path, TRIPLE, TripleController(), text, monkeypatch)
    assert list(doc["kpis"]["iae"]) == ["level", "temp", "pH"]
    assert doc["signals"]["outputs"]["pH"]["unit"] == ""
    assert [ax.get_ylabel() for ax in axes] == ["level [m]", "temp [K]", "pH", "feed [m3/h]",
                                                "heat [kW]"]


@pytest.mark.parametrize(("text", "message"), [
    ("time,ref.h1\n0,300\n100,\n",
     r"sc.csv:1:2: unknown reference 'ref.h1': the controller takes set-points for ref.temp"),
    ("time,ref.temp,sensor.h1.noise\n0,300,0.1\n100,,\n",
     r"sc.csv:1:3: unknown measured output in 'sensor.h1.noise' \(measured: temp\)"),
    ("time,ref.temp,plant.qd1\n0,300,0\n100,,\n",
     r"sc.csv:1:3: unknown plant variable 'plant.qd1'"),
    ("time,ref.temp,plant.power\n0,300,1\n100,,\n",
     r"sc.csv:1:3: column 'plant.power' sets a plant input that the controller drives"),
    ("time,plant.q_loss\n0,0\n100,\n", r"sc.csv:1:1: no column 'ref.temp'"),
])
def test_scenario_columns_are_checked_against_the_problems_signals(
        tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "sc.csv"
    path.write_text(text)
    with pytest.raises(CosimError, match=message):
        Master(FirstOrderPlant(HEATER), HeaterController(), load(path))


@pytest.mark.parametrize(("m", "p"), [(1, 1), (2, 2), (2, 3)])
def test_the_certificate_figure_has_a_panel_per_output_in_its_units(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, m: int, p: int) -> None:
    from controllers.certification import certificates as certs
    from controllers.problem import Channel, ControlProblem
    from tests.controllers.random_gru import random_gru_model

    outs = (Channel("T", "K", 300.0, 360.0), Channel("CA", "mol/L", 0.1, 0.9),
            Channel("pH", "", 2.0, 12.0))[:p]
    problem = ControlProblem(name="other", Ts=15.0, outputs=outs, inputs=(
        Channel("F", "L/min", 2.0, 12.0), Channel("Tc", "K", 280.0, 320.0))[:m])
    model = random_gru_model(3, n=8, problem=problem)
    model.w_y_bar = 0.01
    cert = certs.compute_certificate(model, N=15)
    middle = [0.5 * (c.min + c.max) for c in outs]
    reachable = np.array([middle, [c.max - 0.1 * (c.max - c.min) for c in outs]])
    figures = keep_figures(monkeypatch)
    path = plots.certificate_figure(tmp_path / "cert.png", model, cert, [tuple(middle)],
                                    [c.bounds for c in outs], reachable if p <= 2 else None)
    assert path.stat().st_size > 20_000
    axes = figures[0].axes
    labels = [ax.get_ylabel() for ax in axes]
    # the tightened bounds: one panel per output, last
    assert labels[-p:] == [plots.label(c.name, c.unit) for c in outs]
    admissible = axes[0]
    if p == 1:
        assert admissible.get_xlabel() == "T set-point [K]"
        assert len(admissible.patches) == 1  # the reachable interval
    elif p == 2:
        assert (admissible.get_xlabel(), admissible.get_ylabel()) == (
            "T set-point [K]", "CA set-point [mol/L]")
        assert any(line.get_color() == "orange" for line in admissible.lines)
    else:
        assert [t.get_text() for t in admissible.get_legend().get_texts()] == [
            "T ∈ [300, 360] K", "CA ∈ [0.1, 0.9] mol/L", "pH ∈ [2, 12]"]
