"""``cosim train LOG.csv --problem P.toml`` on data logged on a plant (``cosim.core.logdata``): the
split by a column, by ``--split`` or by whole files (``--val``), several experiments and files
kept apart, a gap or a missing sample ending an experiment, one-line errors for a bad time
column or a bad cell (exit 2), the data's provenance in the model file, and a short record
(1,000 samples) that trains well with the defaults."""

from __future__ import annotations

import hashlib
import json
import signal
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from controllers.model import GRUModel
from cosim.cli import main
from cosim.core.datagen import multilevel_signal

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
    assert train(log, problem, out, "--method", "truncated", "--seq-len", "30", "--history",
                 str(history)) == 0
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
    assert "experiments" not in model.training["scores"]


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
    """Training windows stay inside one experiment, and every score is the free run of each
    experiment from the state estimated from its first samples (the record is not one time
    series)."""
    from controllers.identification.record import Record
    from controllers.identification.report import scores
    from controllers.identification.simulation import simulate, training_windows

    log = write_log(tmp_path / "log.csv", steps=147, experiments=2)
    out = tmp_path / "m.json"
    assert train(log, problem, out, "--split", "0.75,0.125") == 0
    model = GRUModel.load(out)
    rec = model.training
    assert [e["name"] for e in rec["data_file"]["experiments"]] == ["run1", "run2"]
    assert [e["lines"] for e in rec["data_file"]["experiments"]] == [[2, 148], [149, 295]]
    power = np.concatenate([heater(147, 0)[0], heater(147, 1)[0]])
    temp = np.concatenate([heater(147, 0)[1], heater(147, 1)[1]])
    u = model.normalize_u(power.reshape(-1, 1))
    y = model.normalize_y(temp.reshape(-1, 1))
    one = np.repeat(["train", "val", "test"], [110, 18, 19])
    record = Record(u, y, np.concatenate([one, one]), np.repeat([0, 1], 147))
    assert training_windows(record) == [(0, 110), (147, 257)]
    expected = scores(record, simulate(model.params, record), model.y_scale, ["temp"],
                      ["run1", "run2"])
    for s in ("train", "val", "test"):
        assert rec["fit"][s]["temp"] == pytest.approx(expected["splits"][s]["fit"]["temp"],
                                                      abs=1e-9)
    assert [e["name"] for e in rec["scores"]["experiments"]] == ["run1", "run2"]
    for got, want in zip(rec["scores"]["experiments"], expected["experiments"], strict=True):
        assert got["splits"]["test"]["rms"]["temp"] == pytest.approx(
            want["splits"]["test"]["rms"]["temp"], abs=1e-12)
    joined = Record(u, y, record.split, np.zeros(294, dtype=int))  # run2 from run1's state
    assert simulate(model.params, joined)[147] != pytest.approx(
        simulate(model.params, record)[147], abs=1e-6)


def test_a_gap_or_a_missing_sample_ends_an_experiment(tmp_path: Path, problem: Path) -> None:
    """Three samples missing (a gap in time) and an empty cell: no error, the record is cut
    there into parts, each its own experiment, and the provenance says where."""
    log = write_log(tmp_path / "log.csv", steps=200)
    lines = _lines(log)
    del lines[101:104]                 # the rows at 500, 505 and 510 s
    log.write_text("\n".join(lines) + "\n")
    _edit(log, 51, {3: ""})            # line 51: its temperature missing
    out = tmp_path / "m.json"
    assert train(log, problem, out) == 0
    src = GRUModel.load(out).training["data_file"]
    assert src["gaps"] == [{"line": 102, "missing_samples": 3}]
    assert src["missing_sample_lines"] == [51]
    assert [e["name"] for e in src["experiments"]] == ["log", "log#2", "log#3"]
    assert [e["lines"] for e in src["experiments"]] == [[2, 50], [52, 101], [102, 198]]
    assert src["rows"] == 196
    assert len(GRUModel.load(out).training["scores"]["experiments"]) == 3


def test_a_separate_validation_file_and_several_data_files(tmp_path: Path,
                                                           problem: Path) -> None:
    """``cosim train est.csv --val val.csv``: the estimation file trains whole (no split
    column), the validation file validates whole; two DATA files are two experiments."""
    est = write_log(tmp_path / "est.csv", steps=120, seed=0)
    val = write_log(tmp_path / "val.csv", steps=80, seed=5)
    out = tmp_path / "m.json"
    assert train(est, problem, out, "--val", str(val)) == 0
    rec = GRUModel.load(out).training
    files = rec["data_file"]["files"]
    assert [f["split"]["source"] for f in files] == ["every row (train)", "every row (val)"]
    assert rec["data_file"]["split"]["rows"] == {"train": 120, "val": 80, "test": 0}
    assert set(rec["scores"]["splits"]) == {"train", "val"}
    assert [e["name"] for e in rec["scores"]["experiments"]] == ["est", "val"]
    assert rec["comparison"]["split"] == "val" and rec["baseline"]["model"] == "ARX"
    second = write_log(tmp_path / "second.csv", steps=120, seed=9)
    assert main(["train", str(est), str(second), "--problem", str(problem), "--out",
                 str(out), *FAST]) == 0
    rec = GRUModel.load(out).training
    assert [e["name"] for e in rec["scores"]["experiments"]] == ["est", "second"]
    assert rec["data_file"]["split"]["rows"] == {"train": 180, "val": 30, "test": 30}


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
                    "expected Ts = 5 s (or a whole number of samples missing) within 1 %"),
    ("fraction of a step", "log.csv:7:1: non-uniform time step of 12.5 s after 20 s (line "
                           "6), expected Ts = 5 s (or a whole number of samples missing) "
                           "within 1 %"),
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
    ("inf", "log.csv:9:4: inf is not a finite number (column 'temp')"),
    ("text", "log.csv:9:2: 'high' is not a number (column 'power')"),
    ("empty time", "log.csv:9:1: empty value in column 'time'"),
    ("short row", "log.csv:9:4: 3 cells, the header has 4"),
    ("bad split", "log.csv:9:5: split must be one of train, val, test, got 'validation'"),
    ("experiment back", "log.csv:12:5: experiment 'run1' comes back after experiment 'run2' "
                        "(line 11): the rows of one experiment must be consecutive"),
    ("no train rows", "log.csv: no rows in split 'train'"),
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
    elif case == "fraction of a step":  # 25 s missing, the next row at 32.5 s
        write_log(log, steps=100)
        lines = _lines(log)
        del lines[6]
        log.write_text("\n".join(lines) + "\n")
        _edit(log, 7, {0: "32.5"})
    elif case == "restart":  # two records one after the other, without an experiment column
        write_log(log, steps=100)
        log.write_text(log.read_text() + "\n".join(_lines(log)[1:]) + "\n")
    elif case == "wrong Ts":
        write_log(log, steps=100, time=10.0 * np.arange(100))
    elif case == "missing column":
        write_log(log, steps=100)
        log.write_text(log.read_text().replace(",temp", ",temperature", 1))
    elif case in ("inf", "text", "empty time", "short row"):
        write_log(log, steps=100)
        if case == "short row":
            lines = _lines(log)
            lines[8] = lines[8].rsplit(",", 1)[0]
            log.write_text("\n".join(lines) + "\n")
        else:
            col, cell = {"inf": (3, "inf"), "text": (1, "high"), "empty time": (0, "")}[case]
            _edit(log, 9, {col: cell})
    elif case == "bad split":
        write_log(log, steps=100, split=True)
        _edit(log, 9, {4: "validation"})
    elif case == "experiment back":
        write_log(log, steps=10, experiments=2)
        lines = _lines(log)
        lines[10], lines[11] = lines[11], lines[10]  # run2's first row before run1's last
        log.write_text("\n".join(lines) + "\n")
    elif case == "no train rows":
        write_log(log, steps=100, split=True)
        log.write_text(log.read_text().replace(",train\n", ",val\n"))
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
    assert main(["train", str(data), "--out", str(out), *FAST]) == 0
    src = GRUModel.load(out).training["data_file"]
    assert src["problem"] == "fourtank" and src["ignored_columns"] == ["h3", "h4"]
    assert src["split"]["rows"] == {"train": 150, "val": 25, "test": 25}
    assert src["columns"]["inputs"] == ["qa", "qb"] and src["columns"]["outputs"] == ["h1", "h2"]


@pytest.mark.slow
def test_a_short_record_trains_well_with_the_defaults(tmp_path: Path, problem: Path) -> None:
    """1,000 samples (750 / 125 / 125) of the heater, one seed and one size to keep the test
    short: the simulation method (fitted initial states, the free run's error) reaches a
    validation and test RMS well below its ARX baseline's, where the paper's recipe
    (truncated subsequences from x = 0) on the same record and epochs stays above it."""
    log = write_log(tmp_path / "log.csv", steps=1000, seed=0)
    out = tmp_path / "m.json"
    common = ["--problem", str(problem), "--n", "8", "--epochs", "100", "--quiet"]
    assert main(["train", str(log), "--out", str(out), *common]) == 0
    rec = GRUModel.load(out).training
    assert rec["method"] == "simulation" and rec["nu"] < 1
    val, test = rec["scores"]["splits"]["val"], rec["scores"]["splits"]["test"]
    base = rec["baseline"]["scores"]["splits"]
    assert val["rms"]["temp"] < 0.5 * base["val"]["rms"]["temp"]
    assert test["rms"]["temp"] < 0.5 * base["test"]["rms"]["temp"]
    assert test["fit"]["temp"] > 95.0 and not rec["worse_than_baseline"]
    old = tmp_path / "old.json"
    assert main(["train", str(log), "--out", str(old), *common, "--method", "truncated"]) == 0
    old_rec = GRUModel.load(old).training
    assert old_rec["scores"]["splits"]["test"]["rms"]["temp"] > 2 * test["rms"]["temp"]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_training_stops_its_workers_and_writes_nothing(
        sig: signal.Signals, tmp_path: Path, problem: Path) -> None:
    """``cosim train`` fitting its candidates in worker processes, stopped by a signal: exit
    128 + N with one line, within seconds, no worker process left, no model file."""
    import os
    import subprocess
    import sys
    import time

    log = write_log(tmp_path / "log.csv", steps=400)
    out = tmp_path / "m.json"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "train", str(log),
                             "--problem", str(problem), "--out", str(out), "--workers", "2",
                             "--quiet"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(8)                       # the workers are fitting (a full training: minutes)
    children = _children(proc.pid)
    assert proc.poll() is None and len(children) >= 2
    proc.send_signal(sig)
    start = time.monotonic()
    _, err = proc.communicate(timeout=60)
    assert time.monotonic() - start < 15
    assert proc.returncode == 128 + sig, err
    assert err.strip().splitlines()[-1] == f"cosim train: interrupted ({sig.name})"
    assert "Traceback" not in err and not out.exists()
    end = time.monotonic() + 10
    while [p for p in children if os.path.exists(f"/proc/{p}")] and time.monotonic() < end:
        time.sleep(0.2)
    left = {p: Path(f"/proc/{p}/cmdline").read_bytes() for p in children
            if os.path.exists(f"/proc/{p}")}
    assert not left


def _children(pid: int) -> list[int]:
    """The process ids whose parent is ``pid`` (Linux /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out
