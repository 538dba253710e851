"""The shipped campaigns (``scenarios/campaigns/``) parse, match the model they certify, and
run: two runs of each here (the full campaigns and their results: docs/guide/campaigns.md)."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from controllers.model import GRUModel
from cosim.campaign import load, run_campaign

ROOT = Path(__file__).resolve().parents[3]
CAMPAIGNS = sorted((ROOT / "scenarios" / "campaigns").glob("*.toml"))


def test_campaigns_are_shipped() -> None:
    assert {p.stem for p in CAMPAIGNS} >= {"theorem", "plant_uncertainty", "tracking_theorem"}


def test_tracking_campaign_stays_in_the_certified_noise_bound() -> None:
    """Output noise plus the constant disturbance within the model's w̄_y; the first
    set-point certified, the others over the whole output box."""
    spec = load(ROOT / "scenarios" / "campaigns" / "tracking_theorem.toml")
    model = GRUModel.load(spec.plant.removeprefix("model:"))
    draws = {d.key: d for d in spec.draws}
    bias = max(max(abs(v) for v in draws[f"sensor.{o}.bias"].params)
               for o in model.output_names)
    assert draws["plant.w_y_max"].params[0] + bias <= model.w_y_bar
    assert spec.options["law"] == "tracking" and spec.setpoints is not None
    assert spec.setpoints.first_certified and spec.initial_state is not None


@pytest.mark.parametrize("path", CAMPAIGNS, ids=lambda p: p.stem)
def test_shipped_campaign_parses_with_enough_runs(path: Path) -> None:
    spec = load(path)
    assert spec.runs >= 200


def test_theorem_campaign_uses_the_models_own_noise_bound() -> None:
    spec = load(ROOT / "scenarios" / "campaigns" / "theorem.toml")
    model = GRUModel.load(spec.plant.removeprefix("model:"))
    (noise,) = [d for d in spec.draws if d.key == "plant.w_y_max"]
    assert noise.kind == "constant" and noise.params[0] == model.w_y_bar
    assert spec.options["law"] == "paper" and spec.options["governor"] is False
    assert spec.initial_state is not None


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
    if path.stem == "tracking_theorem":     # claims 1-2 of docs/design/tracking.md
        table = result.table
        assert (table["violation_count"] == 0).all()
        assert (table["setpoint_rejected_steps"] == 0).all()
        for run in (tmp_path / "out" / "runs").iterdir():
            ctrl = json.loads((run / "summary.json").read_text())["controller_summary"]
            assert ctrl["fallback_candidates_infeasible"] == 0
        # claim 3 by examples/tracking_theorem.py: y_s in Y_s, the closest admissible one
        sys.path.insert(0, str(ROOT / "examples"))
        try:
            import tracking_theorem
        finally:
            sys.path.pop(0)
        held = tracking_theorem.claims(tracking_theorem.intervals(tmp_path / "out", 41),
                                       2e-3, 0.02)
        assert [h == n for _, h, n, _ in held[:2]] == [True, True], held
