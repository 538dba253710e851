"""Training of a δISS GRU (``controllers.training``, ``cosim train``) on real plant data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from controllers import bounds, training  # noqa: E402
from controllers.errors import ControllersError  # noqa: E402
from controllers.model import GRUModel  # noqa: E402
from cosim import datagen  # noqa: E402
from cosim.cli import main  # noqa: E402
from tests.fourtank_problem import FOURTANK  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FMU = ROOT / "fmus" / "FourTank.fmu"
needs_fmu = pytest.mark.skipif(not FMU.exists(), reason="run 'cosim build-fmu' first")


@pytest.fixture(scope="module")
def short_data(tmp_path_factory) -> Path:
    """1,200 steps of plant data (900 train / 150 val / 150 test) from the FMU."""
    if not FMU.exists():
        pytest.skip("run 'cosim build-fmu' first")
    out = tmp_path_factory.mktemp("data") / "short.csv"
    assert main(["generate-data", "--steps", "1200", "--seed", "3", "--out", str(out),
                 "--quiet"]) == 0
    return out


def normalised(path: Path):
    d = datagen.read_csv(path)
    norm = FOURTANK.normalization()
    u = (d.u - norm["u_offset"]) / norm["u_scale"]
    y = (d.outputs(["h1", "h2"]) - norm["y_offset"]) / norm["y_scale"]
    return u, y, d.split


def random_params(seed: int, n: int = 6) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = training.init_params(n, 2, 2, seed)
    return {k: v + rng.normal(scale=0.5, size=v.shape) for k, v in p.items()}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_torch_nu_equals_numpy_nu(seed):
    p = random_params(seed)
    pt = {k: torch.tensor(v, dtype=torch.float64) for k, v in p.items()}
    assert abs(float(training.nu_torch(pt)) - bounds.nu(p)) < 1e-12


def test_constrain_enforces_the_bound_and_is_differentiable():
    p = random_params(4)
    pt = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in p.items()}
    assert bounds.nu(p) > 1
    q, v_raw = training.constrain(pt, 0.9)
    assert abs(v_raw.item() - bounds.nu(p)) < 1e-12
    assert bounds.nu({k: t.detach().numpy() for k, t in q.items()}) <= 0.9 + 1e-12
    (q["U_h"].sum() + q["U_z"].sum()).backward()
    assert pt["U_h"].grad is not None and torch.any(pt["W_z"].grad != 0)  # through σ̄_z
    # already inside: unchanged
    small = {k: torch.tensor(v) for k, v in training.init_params(6, 2, 2, 0).items()}
    q2, _ = training.constrain(small, 0.9)
    assert torch.equal(q2["U_h"], small["U_h"])


def test_init_params_are_delta_iss():
    for seed in range(3):
        assert bounds.nu(training.init_params(20, 2, 2, seed)) <= 0.5 + 1e-12


def test_refuses_to_build_a_model_with_nu_at_least_one():
    p = random_params(5)
    assert bounds.nu(p) >= 1
    with pytest.raises(ControllersError, match=r"nu = .* >= 1"):
        training.build_model(p, FOURTANK, {})


@pytest.mark.slow
@pytest.mark.parametrize("constraint", ["project", "penalty"])
def test_training_reduces_the_loss_and_stays_delta_iss(short_data, constraint):
    u, y, split = normalised(short_data)
    opts = training.TrainOptions(n=6, seq_len=150, batch=0, epochs=15, lr=2e-2, lr_final=5e-3,
                                 washout=20, constraint=constraint,
                                 penalty_weight=10.0 if constraint == "penalty" else 0.0,
                                 eval_washout=200, seed=1)
    tr = split == "train"
    res = training.train(u[tr], y[tr], u, y, split, opts, progress=False)
    losses = [h["loss"] for h in res.history]
    assert losses[-1] < 0.5 * losses[0]
    assert res.nu < 1
    if constraint == "project":  # every iterate is δISS with the margin
        assert all(h["nu"] <= 1 - opts.nu_margin + 1e-12 for h in res.history)
    assert res.history[res.best_epoch]["fit_val"][0] > 0  # better than the mean
    # deterministic
    again = training.train(u[tr], y[tr], u, y, split, opts, progress=False)
    assert all(np.array_equal(res.params[k], again.params[k]) for k in res.params)


@pytest.mark.slow
def test_cosim_train_writes_a_loadable_model_and_figure(short_data, tmp_path):
    out = tmp_path / "m.json"
    assert main(["train", str(short_data), "--out", str(out), "--n", "5", "--epochs", "3",
                 "--seq-len", "150", "--batch", "0", "--washout", "20", "--quiet"]) == 0
    model = GRUModel.load(out)
    assert model.n == 5 and model.input_names == ["qa", "qb"]
    assert bounds.nu(model.params) < 1
    rec = model.training
    assert rec["nu"] == pytest.approx(bounds.nu(model.params), abs=1e-12)
    assert set(rec["fit"]) == {"train", "val", "test"} and rec["options"]["seq_len"] == 150
    assert model.w_y_bar == pytest.approx(rec["max_abs_err"]["test"])
    assert (tmp_path / "m_test.png").stat().st_size > 10_000


def test_cosim_train_bad_data_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,qa,qb,h1,h2,split\n0,1,2,3,oops,train\n")
    assert main(["train", str(bad), "--out", str(tmp_path / "m.json"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.csv:2: non-numeric value" in err and err.count("\n") == 1
    assert not (tmp_path / "m.json").exists()
