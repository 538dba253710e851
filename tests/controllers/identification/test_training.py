"""Training of a δISS GRU (``controllers.identification.training``, ``cosim train``) on real
plant data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from controllers.certification import bounds  # noqa: E402
from controllers.errors import ControllersError  # noqa: E402
from controllers.identification import metrics, sequences, training  # noqa: E402
from controllers.model import GRUModel  # noqa: E402
from cosim.cli import main  # noqa: E402
from cosim.core import datagen  # noqa: E402
from tests.fourtank_problem import FOURTANK  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
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


@pytest.mark.parametrize("rho_max", [0.8, 0.95])
def test_constrain_caps_the_contraction_rate(rho_max):
    """With ``rho_max``: ρ_s = σ̄_z + (1 − σ̄_z) ν ≤ rho_max (lem:Vs), σ̄_z at most
    ``sigma_cap(rho_max)``, the gradient reaching the gates through the cap."""
    from controllers.identification.contraction import sigma_cap

    p = random_params(5)
    pt = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in p.items()}
    q, _ = training.constrain(pt, 0.98, 0.0, rho_max)
    qn = {k: t.detach().numpy() for k, t in q.items()}
    assert bounds.rho_s(p) > rho_max and bounds.rho_s(qn) <= rho_max + 1e-12
    assert bounds.gate_bounds(qn)[0] <= sigma_cap(rho_max) + 1e-12
    q["U_h"].sum().backward()
    assert torch.any(pt["b_z"].grad != 0)   # ν's room depends on σ̄_z


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
                 "--method", "truncated", "--seq-len", "150", "--batch", "0", "--washout",
                 "20", "--quiet"]) == 0
    model = GRUModel.load(out)
    assert model.n == 5 and model.input_names == ["qa", "qb"]
    assert bounds.nu(model.params) < 1
    rec = model.training
    assert rec["nu"] == pytest.approx(bounds.nu(model.params), abs=1e-12)
    assert set(rec["fit"]) == {"train", "val", "test"} and rec["options"]["seq_len"] == 150
    assert model.w_y_bar == pytest.approx(rec["max_abs_err"]["test"])
    assert (tmp_path / "m_fit.png").stat().st_size > 10_000


def test_cosim_train_bad_data_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,qa,qb,h1,h2,split\n0,1,2,3,oops,train\n")
    assert main(["train", str(bad), "--out", str(tmp_path / "m.json"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.csv:2:5: 'oops' is not a number (column 'h2')" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "m.json").exists()


# --------------------------------------------------------------------------------------------
# Records of several experiments (controllers.identification.sequences) and the defaults of
# short records
# --------------------------------------------------------------------------------------------

def test_training_stretches_and_subsequences_never_span_two_experiments():
    split = np.array(["train"] * 7 + ["val"] * 2 + ["train"] * 3 + ["train"] * 9 + ["test"])
    experiment = np.array([0] * 12 + [1] * 10)
    assert sequences.stretches(split, experiment) == [(0, 7), (9, 12), (12, 21)]
    assert sequences.stretches(split) == [(0, 7), (9, 21)]  # one experiment: joined
    assert sequences.stretches(split, experiment, "val") == [(7, 9)]
    starts = sequences.subsequence_starts(sequences.stretches(split, experiment), 3)
    assert starts == [0, 3, 9, 12, 15, 18]
    rng = np.random.default_rng(0)
    for _ in range(50):  # random layouts: every subsequence inside one experiment's training
        n = int(rng.integers(20, 200))
        split = rng.choice(["train", "val", "test"], n, p=[0.8, 0.1, 0.1])
        experiment = np.cumsum(rng.random(n) < 0.05)
        length = int(rng.integers(1, 8))
        spans = sequences.stretches(split, experiment)
        try:
            starts = sequences.subsequence_starts(spans, length, int(rng.integers(1, 4)))
        except ControllersError:
            assert max((b - a for a, b in spans), default=0) < length
            continue
        for s in starts:
            assert np.all(split[s:s + length] == "train")
            assert np.all(experiment[s:s + length] == experiment[s])
            assert s + length <= n
    with pytest.raises(ControllersError, match="longest training stretch has 3 steps, fewer "
                                               "than seq_len = 4"):
        sequences.subsequence_starts([(0, 3), (5, 8)], 4)


def test_validation_windows_restart_at_each_experiment():
    split = np.array(["train"] * 10 + ["val"] * 3 + ["train"] * 4 + ["val"] * 2)
    experiment = np.array([0] * 13 + [1] * 6)
    assert sequences.eval_windows(split, experiment, "val", 5) == [(5, 13), (13, 19)]
    assert sequences.eval_windows(split, None, "val", 5) == [(5, 19)]


@pytest.mark.parametrize("lengths, given, expected", [
    ([15000], {}, (500, 50, 5, 30)),          # generate-data's default: the paper's settings
    ([750], {}, (75, 7, 2, 10)),               # a record of 1,000 samples, 75 % training
    ([110, 110], {"seq_len": 30}, (30, 3, 1, 6)),
    ([110, 40], {}, (20, 2, 1, 7)),            # T // 10 = 15 < 20: 5 + 2 subsequences
    ([12, 9], {}, (12, 1, 1, 1)),              # the longest stretch caps the length
    ([3000], {"batch": 0, "washout": 0}, (300, 0, 0, 10)),
    ([5000], {"stride": 250}, (500, 50, 3, 19)),
])
def test_record_defaults_follow_the_record(lengths, given, expected):
    d = sequences.record_defaults(lengths, **given)
    assert (d.seq_len, d.washout, d.batch, d.subsequences) == expected


def test_open_loop_restarts_at_each_experiment():
    p = training.init_params(4, 2, 2, 0)
    u = np.random.default_rng(1).uniform(-1, 1, (30, 2))
    experiment = np.repeat([0, 1], [12, 18])
    xi = metrics.open_loop_experiments(p, u, experiment)
    assert np.array_equal(xi[:12], metrics.open_loop(p, u[:12]))
    assert np.array_equal(xi[12:], metrics.open_loop(p, u[12:]))
    assert not np.allclose(xi[12:], metrics.open_loop(p, u)[12:])
    assert np.array_equal(metrics.open_loop_experiments(p, u), metrics.open_loop(p, u))


def test_train_cuts_no_subsequence_across_experiments():
    """Two experiments of 40 training rows: subsequences of 50 would fit in the joined 80."""
    rng = np.random.default_rng(0)
    u, y = rng.uniform(-1, 1, (100, 2)), rng.uniform(-1, 1, (100, 2))
    split = np.tile(np.repeat(["train", "val"], [40, 10]), 2)
    experiment = np.repeat([0, 1], 50)
    tr = split == "train"
    opts = training.TrainOptions(n=3, seq_len=50, washout=5, epochs=1)
    with pytest.raises(ControllersError, match="longest training stretch has 40 steps"):
        training.train(u[tr], y[tr], u, y, split, opts, progress=False, experiment=experiment)
    with pytest.raises(ControllersError, match="the record has 80 training rows"):
        training.train(u[:10], y[:10], u, y, split, opts, progress=False)
