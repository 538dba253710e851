"""A campaign's report keyed by the problem's signals, for plants that are not the four tanks:
``runs.parquet`` columns ``iae.<output>`` …, quantiles, the worst run and ``report.png`` for
p = 1 and p = 3; and a whole campaign (Dask, one worker) on a pythonfmu plant with m = 3,
p = 2."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.campaign import report, run_campaign
from cosim.commands.campaign import _print_summary
from cosim.core import plots, results
from cosim.core.master import Master, RunResult
from cosim.core.scenario import load
from tests.cosim.other_plants import (
    HEATER,
    TRIPLE,
    FirstOrderPlant,
    HeaterController,
    TripleController,
    build_mixer_fmu,
    keep_figures,
)

CASES = {
    "p1": (HEATER, HeaterController, "time,ref.temp\n0,320\n400,330\n800,\n", "plant.q_loss"),
    "p3": (TRIPLE, TripleController, "time,ref.level,ref.temp,ref.pH\n0,1,320,7\n800,,,\n",
           "sensor.temp.bias"),
}


def write_campaign(tmp_path: Path, case: str) -> tuple[Path, list[str]]:
    """Run folders as a campaign writes them: 3 runs × 2 variants (two gains), the draw
    applied at the start, and one run that failed before its first step."""
    problem, controller, text, key = CASES[case]
    runs_dir = tmp_path / "runs"
    for run in range(3):
        for variant, gain in (("fast", 0.3), ("slow", 0.1)):
            value = 0.1 * run
            path = tmp_path / "sc.csv"
            path.write_text(text)
            sc = load(path).with_changes({key: value})
            meta = {"scenario": "sc.csv", "seed": run,
                    "campaign": {"run": run, "variant": variant, "draws": {key: value}}}
            if (run, variant) == (2, "slow"):
                result = RunResult(columns=["time"], rows=[], status="failed",
                                   reason="loading the plant: boom")
            else:
                result = Master(FirstOrderPlant(problem), controller(gain), sc, seed=run).run()
            results.write(runs_dir / report.run_folder_name(run, variant), result, meta,
                          figure=False)
    return runs_dir, [key]


def table_of(runs_dir: Path, keys: list[str]) -> pd.DataFrame:
    """``runs.parquet`` as :func:`cosim.campaign.store.build_report` makes it."""
    docs = [json.loads(p.read_text()) for p in sorted(runs_dir.glob("*/summary.json"))]
    return pd.DataFrame([report.kpi_row(d, keys) for d in docs])


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_report_is_keyed_by_the_problems_signals(tmp_path: Path, case: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    problem = CASES[case][0]
    outputs, inputs = problem.output_names, problem.input_names
    units = problem.units()
    runs_dir, keys = write_campaign(tmp_path, case)
    table = table_of(runs_dir, keys)
    per_signal = ([f"{k}.{o}" for k in ("iae", "final_error", "worst_offset") for o in outputs]
                  + [f"tv.{u}" for u in inputs]
                  + [f"violations.{s}.{f}" for s in [*inputs, *outputs]
                     for f in ("max", "count")])
    assert list(table.columns) == ["run", "seed", "variant", "status", "reason", "tries",
                                   *keys, *report.KPI_COLUMNS, *per_signal]
    assert not [c for c in table.columns if "h1" in c or "h2" in c]
    ok = table[table["status"] == "ok"]
    failed = table[table["status"] == "failed"]
    assert len(ok) == 5 and len(failed) == 1
    assert failed[per_signal].isna().all(axis=None)
    assert (ok[[f"iae.{o}" for o in outputs]] > 0).all(axis=None)
    # the per-output worst offset is the largest over the outputs
    assert np.allclose(ok["worst_offset"], ok[[f"worst_offset.{o}" for o in outputs]].max(axis=1))
    # the column is the run's summary.json path below kpis
    doc = json.loads((runs_dir / "000001-fast" / "summary.json").read_text())
    row = table[(table["run"] == 1) & (table["variant"] == "fast")].iloc[0]
    assert row[f"iae.{outputs[-1]}"] == doc["kpis"]["iae"][outputs[-1]]
    assert row[f"tv.{inputs[0]}"] == doc["kpis"]["tv"][inputs[0]]

    summary = report.summarize(table, "any", 6)
    quantiles = summary["variants"]["fast"]["quantiles"]
    assert list(quantiles) == [*(f"iae.{o}" for o in outputs), "worst_offset",
                               *(f"worst_offset.{o}" for o in outputs), "max_violation",
                               *(f"tv.{u}" for u in inputs), "step_ms_p99", "wall_time_s"]
    assert quantiles[f"iae.{outputs[0]}"]["q50"] == pytest.approx(
        float(np.median(ok[ok["variant"] == "fast"][f"iae.{outputs[0]}"])))
    assert quantiles["step_ms_p99"] is None  # the controller has no solver

    figures = keep_figures(monkeypatch)
    report.write_figure(table, runs_dir, tmp_path / "report.png", "any")
    assert (tmp_path / "report.png").stat().st_size > 20_000
    axes = figures[0].axes
    titles = [ax.get_title() for ax in axes if ax.get_title()]
    for o in outputs:
        iae = f"IAE {o} [{units[o]}·s]" if units[o] else f"IAE {o} [s]"
        assert iae in titles
        offset = f"worst static offset {o} [{units[o]}]" if units[o] else \
            f"worst static offset {o}"
        assert offset in titles
    # the worst run: one panel per output and input, in the problem's units
    labels = [ax.get_ylabel() for ax in axes if ax.get_ylabel()]
    assert labels == [plots.label(s, units[s]) for s in [*outputs, *inputs]]
    worst = report.worst_run(table)
    title = figures[0].subfigs[1].get_suptitle()
    assert title.startswith(f"worst run {int(worst['run']):06d}-{worst['variant']}: ")
    assert all(f"{o} " in title for o in outputs)


def test_units_come_from_a_run_that_has_them_and_no_ok_run_draws_no_worst_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runs_dir, keys = write_campaign(tmp_path, "p1")
    table = table_of(runs_dir, keys)
    failed = table[table["status"] == "failed"].iloc[0]
    signals = report.run_signals(runs_dir, table, failed)  # it has no signals: the next
    assert signals["outputs"] == {"temp": {"unit": "K", "min": 290.0, "max": 350.0}}
    assert report.run_signals(tmp_path / "nowhere", table) == {}
    table["status"] = "failed"
    figures = keep_figures(monkeypatch)
    report.write_figure(table, runs_dir, tmp_path / "report.png", "all failed")
    assert (tmp_path / "report.png").is_file() and not figures[0].subfigs
    assert "IAE temp [K·s]" in [ax.get_title() for ax in figures[0].axes]


def test_the_worst_run_weighs_outputs_in_other_units_alike() -> None:
    table = pd.DataFrame({
        "run": [0, 1, 2, 3], "variant": ["a"] * 4, "status": ["ok", "ok", "ok", "failed"],
        "max_violation": [0.0, 0.0, 0.0, 9.0],
        "iae.big": [1000.0, 1100.0, 900.0, math.nan],    # e.g. K·s
        "iae.small": [1.0, 1.0, 5.0, math.nan],          # e.g. mol/L·s
    })
    # the raw sum would pick run 1; relative to each output's median, run 2 is the worst
    assert int(report.worst_run(table)["run"]) == 2
    table.loc[0, "max_violation"] = 1e-6  # any violation first
    assert int(report.worst_run(table)["run"]) == 0
    table["status"] = "failed"
    assert report.worst_run(table) is None


def test_the_worst_run_breaks_ties_by_run() -> None:
    table = pd.DataFrame({"run": [3, 1, 2], "variant": ["a", "a", "b"], "status": ["ok"] * 3,
                          "max_violation": [0.0] * 3, "iae.y": [2.0] * 3})
    assert int(report.worst_run(table)["run"]) == 1


def test_an_older_summary_gives_the_same_columns() -> None:
    """A run folder written before ``worst_offset`` and ``tv`` (a resumed campaign)."""
    kpis = {"iae": {"y": 3.0}, "final_error": {"y": 0.1}, "violations": {"u": {"max": 0.0,
                                                                             "count": 0}},
            "control_effort": {"u": {"integral_square": 1.0, "total_variation": 2.5}},
            "setpoints": [{"start": 0.0, "end": 1.0, "ref": {"y": 1.0},
                           "offset": {"y": -0.25}}]}
    row = report.kpi_row({"status": "ok", "kpis": kpis}, [])
    assert row["worst_offset.y"] == 0.25 and row["tv.u"] == 2.5
    assert row["violations.u.count"] == 0 and row["iae.y"] == 3.0


@pytest.fixture(scope="module")
def mixer_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_mixer_fmu(tmp_path_factory.mktemp("mixer"))


@pytest.mark.slow
def test_a_campaign_on_a_plant_with_three_inputs_and_two_outputs(
        tmp_path: Path, mixer_fmu: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "mix.csv").write_text("time,ref.T,ref.conc\n0,40,0.3\n600,,\n")
    spec = tmp_path / "mixer.toml"
    spec.write_text(f"""\
[campaign]
name = "mixer"
runs = 2
seed = 5
scenario = "mix.csv"
plant = "{mixer_fmu}"
controller = "tests.cosim.other_plants:MixerController"

[draw]
"plant.loss" = {{ uniform = [0.0, 5.0] }}
"sensor.T.noise" = {{ uniform = [0.0, 0.2] }}

[setpoints]
count = 2
hold = 300
T = [30.0, 60.0]
conc = [0.2, 0.8]
""")
    result = run_campaign(spec, tmp_path / "out", workers=1)
    assert result.status == "ok", result.table["reason"].tolist()
    table = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    for col in ("plant.loss", "sensor.T.noise", "iae.T", "iae.conc", "worst_offset.T",
                "tv.F_hot", "tv.F_cold", "tv.F_acid", "violations.T.max",
                "violations.F_acid.count"):
        assert col in table.columns, col
    assert (table["iae.T"] > 0).all() and (table["tv.F_acid"] > 0).all()
    assert (tmp_path / "out" / "report.png").stat().st_size > 20_000
    quantiles = result.summary["quantiles"]
    assert {"iae.T", "iae.conc", "tv.F_hot", "worst_offset.conc"} <= set(quantiles)
    # the printed summary: the median IAE of each output, in the controller's units
    _print_summary(argparse.Namespace(summary=result.summary, out=result.out,
                                      table=result.table))
    line = capsys.readouterr().out.splitlines()[1]
    name = "tests.cosim.other_plants:MixerController"
    q = result.summary["variants"][name]["quantiles"]
    assert line.startswith(f"  {name}: 2 runs, 0 failed, 0 violating")
    assert line.endswith(f"median IAE T {q['iae.T']['q50']:.4g} degC·s, "
                         f"conc {q['iae.conc']['q50']:.4g} mol/L·s")


@pytest.mark.parametrize(("ranges", "message"), [
    ("T = [30.0, 60.0]\n", r"mixer\.toml: \[setpoints\]: no range for conc \(the scenario "
                           r"sets ref\.conc"),
    ("", r"mixer\.toml: \[setpoints\]: without ranges the set-points are the certified ones "
         r"of the model .*fourtank_gru\.json \(outputs h1, h2\), but the scenario sets T, conc: "
         r"give a range per output, e.g\. T = \[low, high\]"),
])
def test_drawn_setpoints_for_every_output_the_scenario_sets(tmp_path: Path, ranges: str,
                                                           message: str) -> None:
    from cosim.campaign import draws, spec
    from cosim.core.errors import CosimError

    (tmp_path / "mix.csv").write_text("time,ref.T,ref.conc\n0,40,0.3\n600,,\n")
    path = tmp_path / "mixer.toml"
    path.write_text('[campaign]\nruns = 2\nscenario = "mix.csv"\n'
                    'controller = "tests.cosim.other_plants:MixerController"\n\n'
                    f"[setpoints]\ncount = 2\nhold = 300\n{ranges}")
    with pytest.raises(CosimError, match=message):
        draws.DrawContext.build(spec.load(path), 0.0)
