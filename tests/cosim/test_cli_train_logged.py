"""``cosim train LOG.csv --problem P.toml`` on data logged on a plant (``cosim.logdata``): the
split by a column or by ``--split``, several experiments kept apart, one-line errors for a
bad time column or a bad cell (exit 2), the data's provenance in the model file, and a short
record (1,000 samples) that trains well with the defaults that follow its length."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from controllers import metrics
from controllers.model import GRUModel
from cosim.cli import main
from cosim.datagen import multilevel_signal

#: A plant that is not the four tanks: one heater, power [kW] -> temperature [degC], Ts = 5 s.
PROBLEM = """\
[problem]
name = "heater"
Ts = 5.0
[inputs.power]
unit = "kW"
min = 0.0
max = 5.0
[outputs.temp]
unit = "degC"
min = 20.0
max = 80.0
"""
TS = 5.0
FAST = ["--epochs", "1", "--n", "3", "--quiet"]


def heater(steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(power, temp)`` of a stable second-order Wiener plant excited by multilevel steps.

    ``x1⁺ = 0.8 x1 + 0.2 u``, ``x2⁺ = 0.9 x2 + 0.1 x1`` with ``u = (power − 2.5)/2.5``;
    ``temp = 50 + 25 tanh(1.2 x2)`` plus noise of 0.05 degC (seeded).
    """
    rng = np.random.default_rng(seed)
    power = multilevel_signal(steps, [(0.0, 5.0)], rng, (2, 30))[:, 0]
    u = (power - 2.5) / 2.5
    x1 = x2 = 0.0
    temp = np.empty(steps)
    for k in range(steps):
        temp[k] = 50.0 + 25.0 * np.tanh(1.2 * x2) + rng.normal(scale=0.05)
        x1, x2 = 0.8 * x1 + 0.2 * u[k], 0.9 * x2 + 0.1 * x1
    return power, temp


def write_log(path: Path, steps: int = 200, seed: int = 0, experiments: int = 1,
              split: bool = False, time: np.ndarray | None = None) -> Path:
    """A logged CSV: ``time,power,temp,comment`` (+ ``experiment``, ``split``); each
    experiment's time starts again at 0."""
    header = ["time", "power", "comment", "temp"]
    if experiments > 1:
        header.append("experiment")
    if split:
        header.append("split")
    rows = [",".join(header)]
    for e in range(experiments):
        power, temp = heater(steps, seed + e)
        t = TS * np.arange(steps) if time is None else time
        for k in range(steps):
            cells = [repr(float(t[k])), repr(float(power[k])), "note, quoted" if k == 3 else "",
                     repr(float(temp[k]))]
            cells[2] = f'"{cells[2]}"' if cells[2] else "x"
            if experiments > 1:
                cells.append(f"run{e + 1}")
            if split:
                cells.append("train" if k < 0.75 * steps else "val" if k < 0.875 * steps
                             else "test")
            rows.append(",".join(cells))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.fixture
def problem(tmp_path: Path) -> Path:
    path = tmp_path / "heater.toml"
    path.write_text(PROBLEM)
    return path


def train(log: Path, problem: Path, out: Path, *extra: str) -> int:
    return main(["train", str(log), "--problem", str(problem), "--out", str(out), *FAST,
                 *extra])


def test_logged_csv_with_a_split_column(tmp_path: Path, problem: Path) -> None:
    log = write_log(tmp_path / "log.csv", split=True)
    out = tmp_path / "m.json"
    history = tmp_path / "h.csv"
    assert train(log, problem, out, "--seq-len", "30", "--history", str(history)) == 0
    model = GRUModel.load(out)
    assert model.input_names == ["power"] and model.output_names == ["temp"]
    assert model.problem is not None and model.problem.name == "heater" and model.Ts == TS
    src = model.training["data_file"]
    assert src["sha256"] == hashlib.sha256(log.read_bytes()).hexdigest()
    assert src["rows"] == 200 and src["problem"] == "heater" and src["Ts"] == TS
    assert src["columns"] == {"time": "time", "inputs": ["power"], "outputs": ["temp"],
                              "split": "split", "experiment": None}
    assert src["ignored_columns"] == ["comment"]
    assert src["split"] == {"source": "column 'split'",
                            "rows": {"train": 150, "val": 25, "test": 25}}
    assert src["experiments"] == [{"name": None, "rows": 200, "lines": [2, 201],
                                   "time": [0.0, 995.0],
                                   "split": {"train": 150, "val": 25, "test": 25}}]
    # washout and batch follow --seq-len and the record: 30 // 10, 5 subsequences / 6
    opts = model.training["options"]
    assert (opts["seq_len"], opts["washout"], opts["batch"]) == (30, 3, 1)
    assert model.training["subsequences"] == {"count": 5, "training_stretches": 1,
                                              "from_record": ["washout", "batch"]}
    assert history.read_text().splitlines()[0] == (
        "epoch,time_s,loss,nu,fit_val_temp,U_o_inf_norm")
    assert "fit_per_experiment" not in model.training


def test_split_fractions_per_experiment_in_time_order(tmp_path: Path, problem: Path) -> None:
    log = write_log(tmp_path / "log.csv", steps=100, experiments=2, split=True)
    out = tmp_path / "m.json"
    # --split replaces the split column, which becomes an ignored column
    assert train(log, problem, out, "--split", "0.6,0.3") == 0
    src = GRUModel.load(out).training["data_file"]
    assert src["split"]["source"] == "fractions 0.6,0.3 of each experiment in time order (--split)"
    assert src["split"]["rows"] == {"train": 120, "val": 60, "test": 20}
    assert [e["split"] for e in src["experiments"]] == [{"train": 60, "val": 30, "test": 10}] * 2
    assert src["columns"]["split"] is None and src["ignored_columns"] == ["comment", "split"]
    # no split column, no --split: the fractions of generate-data, 75/12.5/12.5 %
    plain = write_log(tmp_path / "plain.csv", steps=200)
    assert train(plain, problem, out) == 0
    src = GRUModel.load(out).training["data_file"]
    assert src["split"]["rows"] == {"train": 150, "val": 25, "test": 25}
    assert src["split"]["source"].endswith("(default, no split column)")


def test_two_experiments_are_kept_apart(tmp_path: Path, problem: Path) -> None:
    """Training subsequences stay inside one experiment, and the open-loop FIT restarts at
    each experiment (the record is not one time series)."""
    log = write_log(tmp_path / "log.csv", steps=147, experiments=2)
    out = tmp_path / "m.json"
    assert train(log, problem, out, "--seq-len", "30", "--split", "0.75,0.125") == 0
    model = GRUModel.load(out)
    rec = model.training
    assert [e["name"] for e in rec["data_file"]["experiments"]] == ["run1", "run2"]
    assert [e["lines"] for e in rec["data_file"]["experiments"]] == [[2, 148], [149, 295]]
    # 110 training rows per experiment: 3 subsequences of 30 each; joined (220): 7
    assert rec["subsequences"]["count"] == 6 and rec["subsequences"]["training_stretches"] == 2
    # the recorded FIT is that of open-loop simulations restarted at each experiment
    power = np.concatenate([heater(147, 0)[0], heater(147, 1)[0]])
    temp = np.concatenate([heater(147, 0)[1], heater(147, 1)[1]])
    u = model.normalize_u(power.reshape(-1, 1))
    y = model.normalize_y(temp.reshape(-1, 1))
    one = np.repeat(["train", "val", "test"], [110, 18, 19])
    split, experiment = np.concatenate([one, one]), np.repeat([0, 1], 147)
    scores = metrics.split_scores(model.params, u, y, split, experiment)
    for s in ("train", "val", "test"):
        assert rec["fit"][s]["temp"] == pytest.approx(scores[s]["fit"][0], abs=1e-9)
    joined = metrics.split_scores(model.params, u, y, split)  # run2 from run1's last state
    assert joined["train"]["fit"][0] != pytest.approx(scores["train"]["fit"][0], abs=1e-6)
    per = metrics.experiment_scores(model.params, u, y, split, experiment)
    assert [r["experiment"] for r in rec["fit_per_experiment"]] == ["run1", "run2"]
    for r, sc in zip(rec["fit_per_experiment"], per, strict=True):
        assert r["fit"]["test"]["temp"] == pytest.approx(sc["test"]["fit"][0], abs=1e-9)


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _edit(path: Path, line: int, cells: dict[int, str]) -> Path:
    """Replace cells (0-based columns) of file line ``line`` (1-based)."""
    lines = _lines(path)
    row = lines[line - 1].split(",")
    for j, cell in cells.items():
        row[j] = cell
    lines[line - 1] = ",".join(row)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("case, message", [
    ("non-uniform", "log.csv:7:1: non-uniform time step of 6 s after 20 s (line 6), "
                    "expected Ts = 5 s within 1 %"),
    ("gap", "log.csv:7:1: gap in time: 20 s (line 6) to 40 s, 3 samples of Ts = 5 s missing; "
            "the record is not joined over a gap: each experiment's rows need their own label "
            "in an 'experiment' column"),
    ("backwards", "log.csv:7:1: time 15 s does not follow 20 s (line 6): time must increase "
                  "by Ts = 5 s; for several experiments, each experiment's rows need their "
                  "own label in an 'experiment' column"),
    ("restart", "log.csv:102:1: time 0 s does not follow 495 s (line 101): time must "
                "increase by Ts = 5 s; for several experiments, each experiment's rows need "
                "their own label in an 'experiment' column"),
    ("wrong Ts", "log.csv:3:1: the data are sampled every 10 s (median time step), but "
                 "problem 'heater' has Ts = 5 s: resample the log at Ts, or give the problem "
                 "of this sample time"),
    ("missing column", "log.csv:1: no column 'temp' (an output of problem 'heater'); the "
                       "header has time, power, comment, temperature"),
    ("nan", "log.csv:9:4: nan is not a finite number (column 'temp')"),
    ("text", "log.csv:9:2: 'high' is not a number (column 'power')"),
    ("empty", "log.csv:9:4: empty value in column 'temp'"),
    ("short row", "log.csv:9:4: 3 cells, the header has 4"),
    ("bad split", "log.csv:9:5: split must be one of train, val, test, got 'validation'"),
    ("experiment back", "log.csv:12:5: experiment 'run1' comes back after experiment 'run2' "
                        "(line 11): the rows of one experiment must be consecutive"),
    ("gap in experiment", "log.csv:106:1: gap in time: 15 s (line 105) to 25 s, 1 sample of "
                          "Ts = 5 s missing; the record is not joined over a gap: give each "
                          "part its own experiment label"),
    ("no val rows", "log.csv: no rows in split 'val'"),
    ("bad --split", "--split must be two fractions TRAIN,VAL with TRAIN > 0, VAL > 0 and "
                    "TRAIN + VAL < 1 (the test part is the rest), got '0.8,0.2'"),
])
def test_bad_logs_are_one_line_errors(case: str, message: str, tmp_path: Path, problem: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    log = tmp_path / "log.csv"
    extra: list[str] = []
    if case in ("non-uniform", "backwards"):
        write_log(log, steps=100)
        _edit(log, 7, {0: {"non-uniform": "26.0", "backwards": "15.0"}[case]})
    elif case == "gap":  # the rows at 25, 30 and 35 s are missing
        write_log(log, steps=100)
        lines = _lines(log)
        del lines[6:9]
        log.write_text("\n".join(lines) + "\n")
    elif case == "restart":  # two records one after the other, without an experiment column
        write_log(log, steps=100)
        log.write_text(log.read_text() + "\n".join(_lines(log)[1:]) + "\n")
    elif case == "wrong Ts":
        write_log(log, steps=100, time=10.0 * np.arange(100))
    elif case == "missing column":
        write_log(log, steps=100)
        log.write_text(log.read_text().replace(",temp", ",temperature", 1))
    elif case in ("nan", "text", "empty", "short row"):
        write_log(log, steps=100)
        if case == "short row":
            lines = _lines(log)
            lines[8] = lines[8].rsplit(",", 1)[0]
            log.write_text("\n".join(lines) + "\n")
        else:
            col, cell = {"nan": (3, "nan"), "text": (1, "high"), "empty": (3, "")}[case]
            _edit(log, 9, {col: cell})
    elif case == "bad split":
        write_log(log, steps=100, split=True)
        _edit(log, 9, {4: "validation"})
    elif case == "experiment back":
        write_log(log, steps=10, experiments=2)
        lines = _lines(log)
        lines[10], lines[11] = lines[11], lines[10]  # run2's first row before run1's last
        log.write_text("\n".join(lines) + "\n")
    elif case == "gap in experiment":
        write_log(log, steps=100, experiments=2)
        lines = _lines(log)
        del lines[105]  # run2's row at t = 20 s
        log.write_text("\n".join(lines) + "\n")
    elif case == "no val rows":
        write_log(log, steps=100, split=True)
        log.write_text(log.read_text().replace(",val\n", ",train\n"))
    elif case == "bad --split":
        write_log(log, steps=100)
        extra = ["--split", "0.8,0.2"]
    out = tmp_path / "m.json"
    assert train(log, problem, out, *extra) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    prefix = "" if case == "bad --split" else f"{tmp_path}/"
    assert err == f"cosim train: error: {prefix}{message}\n"
    assert not out.exists()


def test_a_log_without_its_problem_says_to_give_it(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    log = write_log(tmp_path / "log.csv", steps=50)
    assert main(["train", str(log), "--out", str(tmp_path / "m.json"), *FAST]) == 2
    assert capsys.readouterr().err == (
        f"cosim train: error: {log}:1: no column 'qa' (an input of problem 'fourtank'); the "
        "header has time, power, comment, temp; a logged CSV needs its problem: --problem "
        "PROBLEM.toml\n")


def test_generated_data_set_keeps_its_split_and_records_its_provenance(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A data set in the format of ``cosim generate-data`` (sidecar with the problem): the
    extra plant outputs are ignored columns, the split is its column."""
    from tests.fourtank_problem import FOURTANK

    rng = np.random.default_rng(0)
    rows = ["time,qa,qb,h1,h2,h3,h4,split"]
    for k in range(200):
        split = "train" if k < 150 else "val" if k < 175 else "test"
        values = (25.0 * k, *rng.uniform(1e-4, 9e-4, 2), *rng.uniform(0.3, 1.5, 4))
        rows.append(",".join(repr(float(v)) for v in values) + f",{split}")
    data = tmp_path / "gen.csv"
    data.write_text("\n".join(rows) + "\n")
    data.with_suffix(".json").write_text(json.dumps({"problem": FOURTANK.to_dict()}))
    out = tmp_path / "m.json"
    assert main(["train", str(data), "--out", str(out), *FAST, "--seq-len", "20"]) == 0
    src = GRUModel.load(out).training["data_file"]
    assert src["problem"] == "fourtank" and src["ignored_columns"] == ["h3", "h4"]
    assert src["split"]["rows"] == {"train": 150, "val": 25, "test": 25}
    assert src["columns"]["inputs"] == ["qa", "qb"] and src["columns"]["outputs"] == ["h1", "h2"]


@pytest.mark.slow
def test_a_short_record_trains_well_with_the_defaults(tmp_path: Path, problem: Path) -> None:
    """1,000 samples (750 / 125 / 125) of the heater: subsequence length, washout and batch
    follow the record (75, 7, 2: ten subsequences, five steps per epoch). 60 epochs at a
    learning rate of 0.05 reach test / validation FIT 88.7 / 81.2 % (measured; the paper's
    500 / 50 / 5 on the same record and epochs, one subsequence and one step per epoch:
    83.0 / 67.0 %). About 20 s on one thread."""
    log = write_log(tmp_path / "log.csv", steps=1000, seed=0)
    out = tmp_path / "m.json"
    assert main(["train", str(log), "--problem", str(problem), "--out", str(out),
                 "--epochs", "60", "--lr", "0.05", "--quiet"]) == 0
    rec = GRUModel.load(out).training
    opts = rec["options"]
    assert (opts["seq_len"], opts["washout"], opts["batch"], opts["n"]) == (75, 7, 2, 20)
    assert rec["subsequences"]["count"] == 10
    assert rec["fit"]["test"]["temp"] > 85.0
    assert rec["fit"]["val"]["temp"] > 75.0
    assert rec["nu"] < 1
