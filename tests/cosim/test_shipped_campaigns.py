"""The shipped campaigns (``scenarios/campaigns/``) parse, match the model they certify, and
run: two runs of each here (the full campaigns and their results: docs/guide/campaigns.md)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from controllers.model import GRUModel
from cosim.campaign import load, run_campaign

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGNS = sorted((ROOT / "scenarios" / "campaigns").glob("*.toml"))


def test_campaigns_are_shipped() -> None:
    assert {p.stem for p in CAMPAIGNS} >= {"theorem", "plant_uncertainty"}


@pytest.mark.parametrize("path", CAMPAIGNS, ids=lambda p: p.stem)
def test_shipped_campaign_parses_with_enough_runs(path: Path) -> None:
    spec = load(path)
    assert spec.runs >= 200


def test_theorem_campaign_uses_the_models_own_noise_bound() -> None:
    spec = load(ROOT / "scenarios" / "campaigns" / "theorem.toml")
    model = GRUModel.load(spec.plant.removeprefix("model:"))
    (noise,) = [d for d in spec.draws if d.key == "plant.w_y_max"]
    assert noise.kind == "constant" and noise.params[0] == model.w_y_bar
    assert spec.options["governor"] is False and spec.initial_state is not None


@pytest.mark.slow
@pytest.mark.parametrize("path", CAMPAIGNS, ids=lambda p: p.stem)
def test_two_runs_of_each_shipped_campaign(path: Path, tmp_path: Path) -> None:
    spec = replace(load(path), runs=2)
    result = run_campaign(spec, tmp_path / "out", workers=2)
    assert result.status == "ok", result.summary
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["runs"] == 2 * len(spec.variants) and summary["failed"] == 0
    if path.stem == "theorem":
        table = result.table
        assert (table["observer_checks"] > 100).all()
        assert (table["observer_bound_violations"] == 0).all()
        assert (table["violation_count"] == 0).all()
