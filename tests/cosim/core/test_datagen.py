"""``cosim generate-data``: seeded, split, inside the saturation box, on the real plant FMU."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.core import datagen
from cosim.core.errors import CosimError
from tests.fourtank_problem import FOURTANK

ROOT = Path(__file__).resolve().parents[3]
FMU = ROOT / "fmus" / "FourTank.fmu"
needs_fmu = pytest.mark.skipif(not FMU.exists(), reason="run 'cosim build-fmu' first")


def test_multilevel_signal_is_seeded_piecewise_constant_and_bounded():
    bounds = FOURTANK.input_bounds
    a = datagen.multilevel_signal(3000, bounds, np.random.default_rng(1), (2, 80))
    b = datagen.multilevel_signal(3000, bounds, np.random.default_rng(1), (2, 80))
    c = datagen.multilevel_signal(3000, bounds, np.random.default_rng(2), (2, 80))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    for j, (lo, hi) in enumerate(bounds):
        assert lo <= a[:, j].min() and a[:, j].max() <= hi
        assert a[:, j].max() - a[:, j].min() > 0.8 * (hi - lo)  # the box is covered
        # hold times: runs of equal values between 2 and 80 samples (last run may be cut)
        change = np.flatnonzero(np.diff(a[:, j]) != 0)
        runs = np.diff(np.concatenate([[-1], change]))
        assert runs.min() >= 2 and runs.max() <= 80
        assert runs.min() <= 4 and runs.max() >= 40  # both fast and slow excitation


def test_split_sizes_are_the_papers():
    assert datagen.split_sizes(20000) == (15000, 2500, 2500)
    assert sum(datagen.split_sizes(1001)) == 1001


def test_bad_hold_times_rejected():
    with pytest.raises(CosimError, match="hold times"):
        datagen.multilevel_signal(10, FOURTANK.input_bounds, np.random.default_rng(0), (5, 2))


@needs_fmu
def test_generate_data_from_the_plant_fmu_is_reproducible(tmp_path):
    out_a, out_b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["generate-data", "--steps", "400", "--seed", "7", "--out", str(out_a),
                 "--quiet"]) == 0
    assert main(["generate-data", "--steps", "400", "--seed", "7", "--out", str(out_b),
                 "--quiet"]) == 0
    assert out_a.read_text() == out_b.read_text()
    data = datagen.read_csv(out_a)
    assert data.input_names == ["qa", "qb"]
    assert data.output_names == ["h1", "h2", "h3", "h4"]
    assert [int(np.sum(data.split == s)) for s in datagen.SPLITS] == [300, 50, 50]
    assert list(data.split[:300]) == ["train"] * 300 and data.split[-1] == "test"
    assert np.allclose(np.diff(data.time), FOURTANK.Ts)
    for j, (lo, hi) in enumerate(FOURTANK.input_bounds):
        assert lo <= data.u[:, j].min() and data.u[:, j].max() <= hi
    assert np.all(data.y >= 0) and np.all(data.y < 3)
    # the plant responds: levels move with the inputs
    assert np.ptp(data.y[:, 0]) > 0.1 and np.ptp(data.y[:, 1]) > 0.1
    meta = json.loads(out_a.with_suffix(".json").read_text())
    assert meta["seed"] == 7 and meta["splits"] == {"train": 300, "val": 50, "test": 50}


@needs_fmu
def test_plant_physics_one_step(tmp_path):
    """y[k+1] follows the four-tank ODE from y[k] under u[k] (checked with scipy)."""
    from scipy.integrate import solve_ivp

    out = tmp_path / "d.csv"
    assert main(["generate-data", "--steps", "20", "--seed", "1", "--out", str(out),
                 "--quiet"]) == 0
    d = datagen.read_csv(out)
    S, a, ga, gb, g = 0.06, (1.31e-4, 1.51e-4, 9.27e-5, 8.82e-5), 0.3, 0.4, 9.81

    def rhs(t, h, qa, qb):
        s = np.sqrt(2 * g * np.maximum(h, 0))
        return [(-a[0] * s[0] + a[2] * s[2] + ga * qa) / S,
                (-a[1] * s[1] + a[3] * s[3] + gb * qb) / S,
                (-a[2] * s[2] + (1 - gb) * qb) / S, (-a[3] * s[3] + (1 - ga) * qa) / S]

    for k in (0, 5, 18):
        sol = solve_ivp(rhs, (0, 25), d.y[k], args=tuple(d.u[k]), rtol=1e-10, atol=1e-12)
        assert np.max(np.abs(sol.y[:, -1] - d.y[k + 1])) < 1e-6


def test_missing_plant_is_a_one_line_error(tmp_path, capsys):
    code = main(["generate-data", "--plant", str(tmp_path / "none.fmu"), "--out",
                 str(tmp_path / "x.csv"), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    assert "none.fmu: plant FMU not found" in err and err.count("\n") == 1


def test_read_csv_errors_name_file_and_line(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("time,qa,qb,h1,h2,split\n0,1,2,3,4,train\n25,1,x,3,4,train\n")
    with pytest.raises(CosimError, match=r"d\.csv:3: non-numeric value"):
        datagen.read_csv(path)
    path.write_text("time,qa,qb,h1,h2,split\n0,1,2,3,4,later\n")
    with pytest.raises(CosimError, match=r"d\.csv:2: split must be one of"):
        datagen.read_csv(path)
    path.write_text("t,qa\n")
    with pytest.raises(CosimError, match=r"d\.csv:1: header"):
        datagen.read_csv(path)


@needs_fmu
def test_generate_data_through_a_variable_map(tmp_path):
    """--map converts plant units: here the FMU's h1 is read as if it were in centimetres."""
    vmap = tmp_path / "cm.toml"
    vmap.write_text('[signals.h1]\nvariable = "h1"\nscale = 100.0\n'
                    '[signals.qa]\nvariable = "qa"\nunit = "m3/s"\n')
    plain, mapped = tmp_path / "plain.csv", tmp_path / "mapped.csv"
    assert main(["generate-data", "--steps", "50", "--seed", "2", "--out", str(plain),
                 "--quiet"]) == 0
    assert main(["generate-data", "--steps", "50", "--seed", "2", "--map", str(vmap),
                 "--out", str(mapped), "--quiet"]) == 0
    a, b = datagen.read_csv(plain), datagen.read_csv(mapped)
    assert np.array_equal(a.u, b.u)
    assert np.allclose(b.outputs(["h1"]), a.outputs(["h1"]) / 100.0, rtol=1e-12)
    assert np.array_equal(b.outputs(["h2"]), a.outputs(["h2"]))
    assert json.loads(mapped.with_suffix(".json").read_text())["map"] == str(vmap)


@needs_fmu
@pytest.mark.parametrize("entries, signal, variable", [
    ('[signals.qa]\nvariable = "Fa"\n', "qa", "Fa"),
    # a typo in an entry the run does not use
    ('[signals.qa]\nvariable = "qa"\n[signals.qd3]\nvariable = "qd_3"\n', "qd3", "qd_3"),
], ids=["used", "unused"])
def test_a_map_entry_naming_a_missing_variable_is_a_one_line_error(entries, signal, variable,
                                                                     tmp_path, capsys):
    vmap = tmp_path / "map.toml"
    vmap.write_text(entries)
    code = main(["generate-data", "--steps", "20", "--map", str(vmap), "--out",
                 str(tmp_path / "x.csv"), "--quiet"])
    assert code == 2
    assert capsys.readouterr().err == (f"cosim generate-data: error: {vmap}: signal "
                                       f"'{signal}' -> variable '{variable}': the FMU has no "
                                       "such variable\n")
    assert not (tmp_path / "x.csv").exists()


def test_read_csv_rejects_binary_and_malformed_files(tmp_path):
    path = tmp_path / "d.csv"
    path.write_bytes(b"time,qa,qb,h1,split\n\xd0\x9f\xff\xfe,1,2,3,train\n")
    with pytest.raises(CosimError, match=r"d\.csv:\d+: not a text CSV file"):
        datagen.read_csv(path)
    path.write_text('time,qa,qb,h1,split\n0,1,2,3,"' + "x" * 200_000 + '"\n')
    with pytest.raises(CosimError, match=r"d\.csv:2: malformed CSV \(field larger"):
        datagen.read_csv(path)


def test_read_csv_ignores_a_broken_sidecar(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("time,qa,qb,h1,split\n0,1,2,3,train\n")
    path.with_suffix(".json").write_bytes(b"\xff{not json")
    data = datagen.read_csv(path)
    assert data.input_names == ["qa", "qb"] and data.output_names == ["h1"]
    path.with_suffix(".json").write_text('{"inputs": "qa"}')
    assert datagen.read_csv(path).input_names == ["qa", "qb"]


@pytest.mark.parametrize("args, message", [
    (["--seed", "-1"], "--seed must be a non-negative integer, got -1"),
    (["--out", "{tmp}"], "{tmp}: --out must name a file, but this is a folder"),
    (["--out", "{tmp}/blocker/d.csv"], "{tmp}/blocker/d.csv: --out: '{tmp}/blocker' is not a "
                                       "folder"),
])
def test_bad_generate_data_options_exit_2(args, message, tmp_path, capsys):
    (tmp_path / "blocker").write_text("a file")
    args = [a.format(tmp=tmp_path) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "d.csv")]
    assert main(["generate-data", "--steps", "40", "--quiet", *args]) == 2
    err = capsys.readouterr().err
    assert err == f"cosim generate-data: error: {message.format(tmp=tmp_path)}\n"


@needs_fmu
def test_default_plant_does_not_depend_on_the_current_folder(tmp_path):
    """From any folder, the default --plant is the project's FMU (was fmus/FourTank.fmu
    relative to the current folder: 'plant FMU not found')."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "generate-data", "--steps", "20",
                           "--seed", "3", "--quiet"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "data" / "fourtank.csv"
    assert datagen.read_csv(out).u.shape == (20, 2)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert Path(meta["plant"]) == FMU.resolve()


@pytest.mark.parametrize("args, message", [
    (["--steps", "1000001"], "--steps must be at most 1000000, got 1000001"),
    (["--hold-max", "100000000000000000000"],
     "--hold-max must be in [1, 1000000] samples, got 100000000000000000000"),
    (["--hold-min", "0"], "--hold-min must be in [1, 1000000] samples, got 0"),
    (["--hold-min", "90"], "input qa: hold times must satisfy 1 <= min <= max, got 90 and 80 "
                           "(--hold-min, --hold-max or the problem's 'hold')"),
    (["--out", "{tmp}/d.json"], "{tmp}/d.json: --out must not end in .json: that name is the "
                                "data's JSON sidecar (use .csv)"),
])
def test_bad_generate_data_limits_exit_2(args, message, tmp_path, capsys):
    args = [a.format(tmp=tmp_path) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "d.csv")]
    steps = [] if "--steps" in args else ["--steps", "40"]
    assert main(["generate-data", "--quiet", *steps, *args]) == 2
    message = message.format(tmp=tmp_path)
    assert capsys.readouterr().err == f"cosim generate-data: error: {message}\n"
    assert list(tmp_path.iterdir()) == []


@needs_fmu
def test_failed_write_keeps_the_previous_data_and_sidecar(tmp_path, capsys):
    """The CSV and its sidecar are replaced together: when the sidecar cannot be written
    (here its name is taken by a folder), the previous CSV is left byte-identical."""
    out = tmp_path / "d.csv"
    out.write_text("previous data\n")
    (tmp_path / "d.json").mkdir()
    assert main(["generate-data", "--steps", "20", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"cosim generate-data: failed: {tmp_path / 'd.json'}: cannot write: ")
    assert err.count("\n") == 1
    assert out.read_text() == "previous data\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "d.json"]  # no temp file
    assert list((tmp_path / "d.json").iterdir()) == []


def test_read_csv_ignores_a_deeply_nested_sidecar(tmp_path):
    """Like any unreadable sidecar, a JSON nested too deeply for the parser is ignored."""
    path = tmp_path / "d.csv"
    path.write_text("time,qa,qb,h1,split\n0,1,2,3,train\n")
    path.with_suffix(".json").write_text("[" * 100_000 + "]" * 100_000)
    data = datagen.read_csv(path)
    assert data.input_names == ["qa", "qb"] and data.output_names == ["h1"]
