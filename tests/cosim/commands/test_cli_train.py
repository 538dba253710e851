"""``cosim train`` rejects bad options and output paths before training (exit 2, one line)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from controllers.model import GRUModel
from cosim.cli import main
from tests.fourtank_problem import with_table


def _write_data(path: Path) -> Path:
    """A small data set in the format of ``cosim generate-data`` (400 rows, 75/12.5/12.5)."""
    rng = np.random.default_rng(0)
    rows = ["time,qa,qb,h1,h2,h3,h4,split"]
    for k in range(400):
        split = "train" if k < 300 else "val" if k < 350 else "test"
        u = rng.uniform(1e-4, 9e-4, 2)
        y = rng.uniform(0.3, 1.5, 4)
        rows.append(",".join(repr(float(v)) for v in (25.0 * k, *u, *y)) + f",{split}")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def data(tmp_path: Path) -> Path:
    """A small data set in the format of ``cosim generate-data`` (400 rows, 75/12.5/12.5)."""
    return _write_data(tmp_path / "data.csv")


FAST = ["--epochs", "1", "--n", "3", "--quiet"]
#: The paper's recipe (--method truncated), as briefly.
TRUNCATED = ["--method", "truncated", "--epochs", "1", "--seq-len", "20", "--washout", "5",
             "--quiet"]


@pytest.mark.parametrize("args, message", [
    (["--epochs", "0"], "--epochs must be an integer >= 1, got 0"),
    (["--epochs", "100001"], "--epochs must be an integer <= 100000, got 100001"),
    (["--n", "1001"], "--n must be an integer <= 1000, got 1001"),
    (["--n", "0"], "--n must be an integer >= 1, got 0"),
    (["--seed", str(2**64)], f"--seed must be an integer <= {2**63 - 1}, got {2**64}"),
    (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["--method", "truncated", "--stride", "0"], "--stride must be an integer >= 1, got 0"),
    (["--method", "truncated", "--batch", "-1"], "--batch must be an integer >= 0, got -1"),
    (["--seq-len", "30"], "--seq-len belongs to --method truncated (the default simulation "
                          "method fits whole windows from fitted initial states)"),
    (["--seeds", "0"], "--seeds must be an integer >= 1, got 0"),
    (["--x0-samples", "0"], "--x0-samples must be an integer >= 1, got 0"),
    (["--sizes", "4,x"], "give --n (one size) or --sizes (several), not both"),
    (["--patience", "-2"], "--patience must be an integer >= 0, got -2"),
    (["--lr", "nan"], "--lr must be a positive number, got nan"),
    (["--lr-final", "0"], "--lr-final must be a positive number, got 0.0"),
    (["--uo-max", "-1"], "--uo-max must be a non-negative number, got -1.0"),
    (["--bz-init", "inf"], "--bz-init must be a finite number, got inf"),
    (["--sigma-z-max", "1"], "--sigma-z-max must be in [0, 1), got 1.0"),
    (["--rho-max", "0.5"], "--rho-max must be 0 (no cap) or in (0.5, 1), got 0.5"),
    (["--polish", "-1"], "--polish must be an integer >= 0, got -1"),
])
def test_bad_numeric_options_exit_2(args: list[str], message: str, data: Path, tmp_path: Path,
                                    capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "m.json"
    assert main(["train", str(data), "--out", str(out), *FAST, *args]) == 2
    assert capsys.readouterr().err == f"cosim train: error: {message}\n"
    assert not out.exists()


@pytest.mark.parametrize("option, target, message", [
    ("--out", "outdir", "--out must name a file, but this is a folder"),
    ("--out", "blocker/m.json", "--out: '{tmp}/blocker' is not a folder"),
    ("--figure", "fig.csv", "--figure: unknown figure type '.csv'"),
    ("--history", "outdir", "--history must name a file, but this is a folder"),
])
def test_bad_output_paths_exit_2_before_training(option: str, target: str, message: str,
                                                 data: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "outdir").mkdir()
    (tmp_path / "blocker").write_text("a file")
    args = ["--out", str(tmp_path / "m.json")] if option != "--out" else []
    code = main(["train", str(data), *FAST, *args, option, str(tmp_path / target)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"cosim train: error: {tmp_path / target}: ")
    assert message.format(tmp=tmp_path) in err and err.count("\n") == 1
    assert not (tmp_path / "m.json").exists()


def test_broken_sidecar_does_not_fail_after_training(data: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    data.with_suffix(".json").write_text("{not json")
    out = tmp_path / "new" / "m.json"
    assert main(["train", str(data), "--out", str(out), *FAST]) == 0
    assert out.is_file() and (tmp_path / "new" / "m_fit.png").is_file()


FAST_SMALL = FAST


def test_default_out_is_in_the_current_folder_never_the_shipped_model(
        data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """Without --out the model goes to models/<data stem>_gru.json in the current folder
    (was controllers/models/fourtank_gru.json: the shipped model, from the repo root)."""
    from cosim.commands import train

    shipped = train.SHIPPED_MODEL.read_bytes()
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["train", str(data), *FAST_SMALL]) == 0
    assert GRUModel.load(work / "models" / "data_gru.json").n == 3
    assert (work / "models" / "data_gru_fit.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in work.rglob("*")) == ["data_gru.json", "data_gru_fit.png",
                                                       "models"]
    assert train.SHIPPED_MODEL.read_bytes() == shipped
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "models/<DATA stem>_gru.json" in capsys.readouterr().out


def test_shipped_model_is_replaced_only_when_named_with_out(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """Where the default --out resolves to the shipped model (a stand-in here: the real one
    is never touched by this test), training is refused before it starts; naming the file
    with --out replaces it."""
    from cosim.commands import train

    controllers = tmp_path / "controllers"
    shipped = controllers / "models" / "fourtank_gru.json"
    shipped.parent.mkdir(parents=True)
    shipped.write_text("the shipped model")
    monkeypatch.setattr(train, "SHIPPED_MODEL", shipped)
    csv = _write_data(tmp_path / "fourtank.csv")
    monkeypatch.chdir(controllers)
    assert main(["train", str(csv), *FAST_SMALL]) == 2
    assert capsys.readouterr().err == (
        "cosim train: error: models/fourtank_gru.json: the default --out is the shipped model "
        "here; give --out models/fourtank_gru.json explicitly to replace it, or another --out\n")
    assert shipped.read_text() == "the shipped model"
    assert sorted(p.name for p in controllers.rglob("*")) == ["fourtank_gru.json", "models"]
    assert main(["train", str(csv), *FAST_SMALL, "--out", "models/fourtank_gru.json"]) == 0
    assert GRUModel.load(shipped).n == 3


def test_history_is_replaced_only_when_training_ends(data: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    history = tmp_path / "h" / "history.csv"
    history.parent.mkdir()
    history.write_text("previous\n")
    out = tmp_path / "m.json"
    # training fails at its start (subsequences longer than the data): history unchanged
    assert main(["train", str(data), *TRUNCATED, "--n", "3", "--seq-len", "5000", "--out",
                 str(out), "--history", str(history)]) == 2
    assert "fewer than --seq-len 5000" in capsys.readouterr().err
    assert history.read_text() == "previous\n" and not out.exists()
    assert [p.name for p in history.parent.iterdir()] == ["history.csv"]  # no temp file
    assert main(["train", str(data), *TRUNCATED, "--n", "3", "--epochs", "3", "--out",
                 str(out), "--history", str(history)]) == 0
    lines = history.read_text().splitlines()
    assert lines[0].startswith("epoch,time_s,loss,nu") and len(lines) == 4
    assert [p.name for p in history.parent.iterdir()] == ["history.csv"]
    # the simulation method: each candidate's evaluations, written when training ends
    assert main(["train", str(data), *FAST_SMALL, "--epochs", "10", "--out", str(out),
                 "--history", str(history)]) == 0
    lines = history.read_text().splitlines()
    assert lines[0] == "n,seed,rho_max,step,time_s,score_rms"
    caps = [line.split(",")[2] for line in lines[1:]]   # the derived cap, then none
    assert caps[6:] == ["0"] * 6 and float(caps[0]) > 0.5 and len(set(caps[:6])) == 1
    assert [line.split(",")[3] for line in lines[1:]] == ["0", "25", "50", "60", "85", "96"] * 2


def test_deeply_nested_sidecar_and_init_model(data: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    deep = "[" * 100_000 + "]" * 100_000
    data.with_suffix(".json").write_text(deep)  # ignored, like any unreadable sidecar
    out = tmp_path / "m.json"
    assert main(["train", str(data), *FAST_SMALL, "--out", str(out)]) == 0
    assert GRUModel.load(out).training["data_meta"] is None
    capsys.readouterr()
    init = tmp_path / "init.json"
    init.write_text(deep)
    assert main(["train", str(data), *FAST_SMALL, "--out", str(out), "--init",
                 str(init)]) == 2
    assert capsys.readouterr().err == (f"cosim train: error: {init}: invalid model file (JSON "
                                       "nested too deeply)\n")


# -- the problem file's [train] table: this plant's modelling choices ---------------------------

def test_the_problems_train_table_sets_options_the_command_line_overrides(
        data: Path, tmp_path: Path) -> None:
    problem = with_table(tmp_path, "train",
                         "n = 2\nepochs = 1\nsigma_z_max = 0.9\nrho_max = 0.95\n")
    out = tmp_path / "a.json"
    assert main(["train", str(data), "--problem", str(problem), "--out", str(out),
                 "--quiet"]) == 0
    model = GRUModel.load(out)
    assert model.n == 2 and model.problem.train == {"n": 2, "epochs": 1, "sigma_z_max": 0.9,
                                                    "rho_max": 0.95}
    assert model.training["options"]["sigma_z_max"] == 0.9
    assert model.training["contraction"] == {"rho_max": 0.95, "source": "given"}
    out = tmp_path / "b.json"
    assert main(["train", str(data), "--problem", str(problem), "--out", str(out), "--n", "3",
                 "--sigma-z-max", "0", "--rho-max", "0", "--quiet"]) == 0
    model = GRUModel.load(out)
    assert model.n == 3 and model.training["options"]["sigma_z_max"] == 0.0
    assert model.training["options"]["rho_max"] == 0.0
    sizes = with_table(tmp_path, "train", "sizes = [2, 5]\nseeds = 1\nepochs = 1\n")
    out = tmp_path / "c.json"
    assert main(["train", str(data), "--problem", str(sizes), "--out", str(out), "--n", "3",
                 "--quiet"]) == 0                    # --n replaces the table's sizes
    assert GRUModel.load(out).n == 3


@pytest.mark.parametrize("table, anchor, message", [
    ("sigma_z_max = 1.5\n", "sigma_z_max", "[train] sigma_z_max: must be in [0, 1), got 1.5"),
    ("n = 2.5\n", "n = 2.5", "[train] n must be an integer, got 2.5"),
    ("hidden = 3\n", "hidden", "[train] has no option 'hidden' (options: epochs, n, sizes"),
    ('sizes = [4, "x"]\n', "sizes", "[train] sizes must be a list of GRU sizes"),
])
def test_a_bad_train_table_names_the_problem_file_and_line(
        table: str, anchor: str, message: str, data: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture) -> None:
    problem = with_table(tmp_path, "train", "epochs = 1\n" + table)
    text = problem.read_text()
    line = text[:text.index(anchor, text.index("[train]"))].count("\n") + 1
    out = tmp_path / "m.json"
    assert main(["train", str(data), "--problem", str(problem), "--out", str(out),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"cosim train: error: {problem}:{line}: {message}"), err
    assert err.count("\n") == 1 and not out.exists()


def test_the_measured_offset_filter_goes_into_the_models_mpc_table(data: Path,
                                                                    tmp_path: Path) -> None:
    """White outputs (the data's levels drawn anew each sample): the residual is mostly
    noise, the offset filter measured small (measured here: 0.05, the smallest, from h1; h2's
    alone would give 0.22), written into the model's ``[mpc]`` table and the training record;
    a problem file's own ``offset_filter`` is kept."""
    out = tmp_path / "a.json"
    assert main(["train", str(data), "--out", str(out), *FAST]) == 0
    model = GRUModel.load(out)
    record = model.training["prediction_error"]
    beta = record["offset_filter"]
    assert record["offset_filter_from"] == "measured" and 0.05 <= beta <= 0.25, record
    assert model.problem.mpc == {"offset_filter": beta}
    assert set(record["sensor_noise"]) == {"h1", "h2"}
    problem = with_table(tmp_path, "mpc", "offset_filter = 0.7\n")
    assert main(["train", str(data), "--problem", str(problem), "--out", str(out), *FAST]) == 0
    assert GRUModel.load(out).problem.mpc == {"offset_filter": 0.7}
