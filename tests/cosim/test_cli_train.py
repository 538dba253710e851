"""``cosim train`` rejects bad options and output paths before training (exit 2, one line)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main


@pytest.fixture
def data(tmp_path: Path) -> Path:
    """A small data set in the format of ``cosim generate-data`` (400 rows, 75/12.5/12.5)."""
    rng = np.random.default_rng(0)
    rows = ["time,qa,qb,h1,h2,h3,h4,split"]
    for k in range(400):
        split = "train" if k < 300 else "val" if k < 350 else "test"
        u = rng.uniform(1e-4, 9e-4, 2)
        y = rng.uniform(0.3, 1.5, 4)
        rows.append(",".join(repr(float(v)) for v in (25.0 * k, *u, *y)) + f",{split}")
    path = tmp_path / "data.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


FAST = ["--epochs", "1", "--seq-len", "20", "--washout", "5", "--quiet"]


@pytest.mark.parametrize("args, message", [
    (["--epochs", "0"], "--epochs must be an integer >= 1, got 0"),
    (["--n", "0"], "--n must be an integer >= 1, got 0"),
    (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["--stride", "0"], "--stride must be an integer >= 1, got 0"),
    (["--batch", "-1"], "--batch must be an integer >= 0, got -1"),
    (["--patience", "-2"], "--patience must be an integer >= 0, got -2"),
    (["--lr", "nan"], "--lr must be a positive number, got nan"),
    (["--lr-final", "0"], "--lr-final must be a positive number, got 0.0"),
    (["--uo-max", "-1"], "--uo-max must be a non-negative number, got -1.0"),
    (["--bz-init", "inf"], "--bz-init must be a finite number, got inf"),
    (["--sigma-z-max", "1"], "--sigma-z-max must be in [0, 1), got 1.0"),
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
    assert out.is_file() and (tmp_path / "new" / "m_test.png").is_file()
