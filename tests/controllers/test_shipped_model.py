"""The shipped model ``controllers/models/fourtank_gru.json``: δISS and better than the paper."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest

from controllers.certification import bounds
from controllers.identification import metrics
from controllers.model import GRUModel
from cosim.cli import main
from cosim.core import datagen
from tests.fourtank_problem import FOURTANK

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "controllers" / "models" / "fourtank_gru.json"
FMU = ROOT / "fmus" / "FourTank.fmu"
#: Test FIT of the paper's GRU (section V), percent.
PAPER_FIT = {"h1": 92.7, "h2": 89.7}


@pytest.fixture(scope="module")
def model() -> GRUModel:
    return GRUModel.load(MODEL)


def test_shipped_model_is_the_papers_structure(model):
    assert (model.n, model.m, model.p) == (20, 2, 2)
    assert model.input_names == list(FOURTANK.input_names)
    assert model.output_names == list(FOURTANK.output_names)
    assert model.problem == FOURTANK   # the problem travels in the model file
    assert model.Ts == FOURTANK.Ts
    lo = np.array([b[0] for b in FOURTANK.input_bounds])
    hi = np.array([b[1] for b in FOURTANK.input_bounds])
    assert np.allclose(model.normalize_u(lo), -1) and np.allclose(model.normalize_u(hi), 1)


def test_shipped_model_is_delta_iss(model):
    nu = bounds.nu(model.params)
    assert nu < 1
    assert model.training["nu"] == pytest.approx(nu, abs=1e-12)


def test_recorded_test_fit_beats_the_paper(model):
    fit = model.training["fit"]["test"]
    for name, paper in PAPER_FIT.items():
        assert fit[name] > paper, f"{name}: {fit[name]:.2f} % <= paper {paper} %"
    assert model.w_y_bar == pytest.approx(model.training["max_abs_err"]["test"])


@pytest.mark.skipif(not FMU.exists(), reason="run 'cosim build-fmu' first")
def test_test_fit_recomputed_from_fresh_plant_data(model, tmp_path):
    """Regenerate the data set with the recorded command and re-score the model."""
    meta = model.training["data_meta"]
    out = tmp_path / "fresh.csv"
    args = ["generate-data", "--steps", str(meta["steps"]), "--seed", str(meta["seed"]),
            "--hold-min", str(meta["hold"][0]), "--hold-max", str(meta["hold"][1]),
            "--out", str(out), "--quiet"]
    assert main(args) == 0, shlex.join(args)
    data = datagen.read_csv(out)
    u = model.normalize_u(data.u)
    y = model.normalize_y(data.outputs(model.output_names))
    scores = metrics.split_scores(model.params, u, y, data.split)
    for split in ("val", "test"):
        for j, name in enumerate(model.output_names):
            recorded = model.training["fit"][split][name]
            assert scores[split]["fit"][j] == pytest.approx(recorded, abs=1e-6)
    assert scores["test"]["max_abs_err"] == pytest.approx(model.w_y_bar, abs=1e-8)
