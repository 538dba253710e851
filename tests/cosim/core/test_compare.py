"""``cosim compare`` and :mod:`cosim.core.compare`: verdicts, band semantics, resampling, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.core.compare import compare, read_table, resample, window_extrema
from cosim.core.errors import CosimError

T = np.arange(0.0, 500.0, 25.0)


def write(path: Path, time, columns: dict[str, np.ndarray], quote: bool = False) -> Path:
    names = ["time", *columns]
    header = ",".join(f'"{n}"' if quote else n for n in names)
    lines = [header] + [",".join(repr(float(v)) for v in [t, *(c[i] for c in columns.values())])
                        for i, t in enumerate(time)]
    path.write_text("\n".join(lines) + "\n")
    return path


def step(t0: float, time=T, lo: float = 0.5, hi: float = 1.0) -> np.ndarray:
    return np.where(time >= t0, hi, lo)


@pytest.fixture
def ref(tmp_path: Path) -> Path:
    return write(tmp_path / "ref.csv", T, {"h1": step(100), "qa": 1e-4 * step(200)},
                 quote=True)


# -- verdicts and exit codes ----------------------------------------------------------------

def test_identical_files_pass_with_exit_0(ref: Path, capsys) -> None:
    assert main(["compare", str(ref), str(ref)]) == 0
    out = capsys.readouterr().out
    assert "PASS: all 2 signals within the tolerance band" in out
    assert out.count("PASS") == 3  # two table rows and the verdict


def test_deviation_inside_tolerance_passes(tmp_path: Path, ref: Path) -> None:
    res = write(tmp_path / "res.csv", T, {"h1": step(100) * (1 + 5e-5), "qa": 1e-4 * step(200)})
    assert compare(res, ref).passed
    assert not compare(res, ref, rtol=1e-5).passed
    assert compare(res, ref, rtol=0.0, atol=1e-4).passed


def test_failure_report_is_a_table_with_the_worst_time(tmp_path: Path, ref: Path,
                                                      capsys) -> None:
    h1 = step(100).copy()
    h1[10] += 0.01   # t = 250
    h1[12] += 0.03   # t = 300: the worst
    res = write(tmp_path / "res.csv", T, {"h1": h1, "qa": 1e-4 * step(200)})
    assert main(["compare", str(res), str(ref)]) == 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    header = next(line for line in lines if line.startswith("signal"))
    assert all(w in header for w in ("max |dev|", "at t [s]", "outside", "verdict"))
    row = next(line for line in lines if line.startswith("h1 "))
    assert "0.03" in row and "300" in row and "2/20 (10.0%)" in row and row.endswith("FAIL")
    assert next(line for line in lines if line.startswith("qa ")).endswith("PASS")
    assert ("FAIL h1: 2 of 20 points outside (10.0%), first at t = 250 s, worst at t = 300 s: "
            "result 1.03, reference 1") in out
    assert lines[-1] == "FAIL: 1 of 2 signals outside the tolerance band ('h1')"


def test_quiet_prints_only_failures(tmp_path: Path, ref: Path, capsys) -> None:
    assert main(["compare", str(ref), str(ref), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    res = write(tmp_path / "res.csv", T, {"h1": step(100) + 0.1, "qa": 1e-4 * step(200)})
    assert main(["compare", str(res), str(ref), "--quiet"]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("FAIL h1:") and out[-1].startswith("FAIL: 1 of 2")


def test_signals_option_selects(tmp_path: Path, ref: Path) -> None:
    res = write(tmp_path / "res.csv", T, {"h1": step(100) + 0.1, "qa": 1e-4 * step(200)})
    assert main(["compare", str(res), str(ref), "--signals", "qa"]) == 0
    assert main(["compare", str(res), str(ref), "--signals", "qa,h1"]) == 1


def test_per_signal_tolerances(tmp_path: Path, ref: Path) -> None:
    res = write(tmp_path / "res.csv", T, {"h1": step(100) + 1e-3, "qa": 1e-4 * step(200)})
    assert main(["compare", str(res), str(ref), "--atol", "1e-9,h1=2e-3"]) == 0
    assert main(["compare", str(res), str(ref), "--atol", "h1=1e-4"]) == 1
    c = compare(res, ref, atol={"h1": 2e-3})
    assert c.passed and c.signals[0].atol == 2e-3 and c.signals[1].atol == 1e-9


# -- band semantics ---------------------------------------------------------------------------

def test_band_tolerates_a_one_sample_time_shift(tmp_path: Path, ref: Path, capsys) -> None:
    shifted = write(tmp_path / "shift.csv", T, {"h1": step(125), "qa": 1e-4 * step(175)})
    assert main(["compare", str(shifted), str(ref)]) == 1
    capsys.readouterr()
    assert main(["compare", str(shifted), str(ref), "--band"]) == 0
    assert "band: reference min/max over ±25 s" in capsys.readouterr().out
    late = write(tmp_path / "late.csv", T, {"h1": step(175), "qa": 1e-4 * step(200)})
    assert main(["compare", str(late), str(ref), "--band"]) == 1       # 3 samples late
    assert main(["compare", str(late), str(ref), "--band", "--window", "75"]) == 0


def test_band_is_widened_by_atol_plus_rtol_times_range(tmp_path: Path) -> None:
    t = np.arange(0.0, 100.0, 10.0)
    ref = write(tmp_path / "ref.csv", t, {"y": np.linspace(0.0, 10.0, t.size)})  # range 10
    # Constant offset 0.05 above a straight line: outside the ±1-sample window's max only at
    # the last point (where the window is clipped), by 0.05.
    res = write(tmp_path / "res.csv", t, {"y": np.linspace(0.0, 10.0, t.size) + 0.05})
    assert not compare(res, ref, band=True, rtol=0.0, atol=0.04).passed
    assert compare(res, ref, band=True, rtol=0.0, atol=0.06).passed
    assert compare(res, ref, band=True, rtol=0.006, atol=0.0).passed   # 0.006 · 10 = 0.06
    c = compare(res, ref, band=True, rtol=0.0, atol=0.04)
    assert c.signals[0].n_outside == 1 and c.signals[0].time[c.signals[0].worst] == 90.0


def test_window_extrema_of_a_piecewise_linear_signal() -> None:
    t = np.array([0.0, 10.0, 20.0])
    y = np.array([0.0, 10.0, 0.0])
    lo, hi = window_extrema(t, y, np.array([0.0, 5.0, 15.0, 20.0]), 2.0)
    np.testing.assert_allclose(lo, [0.0, 3.0, 3.0, 0.0])
    np.testing.assert_allclose(hi, [2.0, 7.0, 7.0, 2.0])


# -- resampling -----------------------------------------------------------------------------

def test_resample_is_exact_at_samples_and_linear_between() -> None:
    t = np.array([0.0, 1.0, 3.0])
    y = np.array([0.1, 0.7, 2.0])
    out = resample(t, y, np.array([-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 3.5]))
    assert np.isnan(out[0]) and np.isnan(out[-1])
    assert out[1] == 0.1 and out[3] == 0.7 and out[5] == 2.0
    np.testing.assert_allclose(out[[2, 4]], [0.4, 1.35])
    # A NaN neighbour does not spoil the exact value at a sample.
    assert resample(t, np.array([1.0, 2.0, np.nan]), np.array([1.0]))[0] == 2.0


def test_different_grids_are_compared_on_their_union(tmp_path: Path) -> None:
    fine = np.arange(0.0, 101.0, 5.0)
    coarse = np.arange(0.0, 101.0, 20.0)
    ramp = write(tmp_path / "ref.csv", coarse, {"y": 2.0 * coarse})
    res = write(tmp_path / "res.csv", fine, {"y": 2.0 * fine})
    c = compare(res, ramp)
    assert c.passed and c.signals[0].n_points == fine.size
    bumped = 2.0 * fine
    bumped[3] += 1.0   # t = 15 s, between two reference samples
    c = compare(write(tmp_path / "bump.csv", fine, {"y": bumped}), ramp)
    assert not c.passed and c.signals[0].time[c.signals[0].worst] == 15.0


def test_shorter_result_fails_on_the_uncovered_times(tmp_path: Path, ref: Path, capsys) -> None:
    res = write(tmp_path / "res.csv", T[:10], {"h1": step(100)[:10], "qa": 1e-4 * step(200)[:10]})
    assert main(["compare", str(res), str(ref)]) == 1
    out = capsys.readouterr().out
    assert "covers only t = 0..225 s of 0..475 s" in out
    assert "10/20 (50.0%)" in out and "only one file has a value there" in out


def test_nan_matches_only_nan(tmp_path: Path) -> None:
    t = np.array([0.0, 1.0, 2.0])
    ref = write(tmp_path / "ref.csv", t, {"y": np.array([1.0, np.nan, 2.0])})
    assert compare(ref, ref).passed
    res = write(tmp_path / "res.csv", t, {"y": np.array([1.0, 1.5, 2.0])})
    c = compare(res, ref)
    assert not c.passed and c.signals[0].outside.tolist() == [False, True, False]


# -- errors: exit 2 with file:line:column -------------------------------------------------------

@pytest.mark.parametrize(("text", "message"), [
    ("", "res.csv:1:1: empty file"),
    ("time,h1\n", "res.csv:2:1: no data rows"),
    ("time,h1\n0,1\n25,abc\n", "res.csv:3:2: 'abc' is not a number (column 'h1')"),
    ("time,h1\n0,1\n25,\n", "res.csv:3:2: empty value in column 'h1'"),
    ("time,h1\n0,1\n0,2\n", "res.csv:3:1: time 0 is not greater than the previous time 0"),
    ("time,h1\n25,1\n0,2\n", "res.csv:3:1: time 0 is not greater"),
    ("time,h1\n0,1,2\n", "res.csv:2:1: 3 cells, the header has 2"),
    ("time,h1,h1\n0,1,2\n", "res.csv:1:3: duplicate column 'h1'"),
    ("time,h1\nx,1\n", "res.csv:2:1: 'x' is not a number (column 'time')"),
    ("time,h1\nnan,1\n", "res.csv:2:1: time must be finite"),
])
def test_bad_csv_is_an_error_naming_file_line_column(tmp_path: Path, ref: Path, capsys,
                                                     text: str, message: str) -> None:
    res = tmp_path / "res.csv"
    res.write_text(text)
    assert main(["compare", str(res), str(ref), "--signals", "h1"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_missing_file_and_missing_signals_are_errors(tmp_path: Path, ref: Path, capsys) -> None:
    assert main(["compare", str(tmp_path / "nope.csv"), str(ref)]) == 2
    assert "nope.csv: no such file" in capsys.readouterr().err
    other = write(tmp_path / "other.csv", T, {"h1": step(100), "qb": step(100)})
    assert main(["compare", str(other), str(ref)]) == 2
    err = capsys.readouterr().err
    assert "lacks 'qa'" in err and "lacks 'qb'" in err and "common: 'h1'" in err
    assert main(["compare", str(other), str(ref), "--signals", "h1"]) == 0
    assert main(["compare", str(other), str(ref), "--signals", "h2"]) == 2
    assert "no signal 'h2'" in capsys.readouterr().err
    disjoint = write(tmp_path / "disjoint.csv", T, {"x": step(100)})
    assert main(["compare", str(disjoint), str(ref)]) == 2
    assert "no signal in common" in capsys.readouterr().err


def test_bad_options_are_errors(ref: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["compare", str(ref), str(ref), "--rtol", "-1"])
    assert exc.value.code == 2
    assert main(["compare", str(ref), str(ref), "--window", "5"]) == 2
    assert "--window applies only with --band" in capsys.readouterr().err


def test_read_table_parses_columns_lazily(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text('"time","ok","text"\n0,1,abc\n25,2,def\n')
    table = read_table(path)
    assert table.names == ["ok", "text"] and table.column("ok").tolist() == [1.0, 2.0]
    with pytest.raises(CosimError, match=r"r.csv:2:3: 'abc' is not a number"):
        table.column("text")


# -- plot -------------------------------------------------------------------------------------

def test_plot_is_written(tmp_path: Path, ref: Path, capsys) -> None:
    res = write(tmp_path / "res.csv", T, {"h1": step(125), "qa": 1e-4 * step(200)})
    png = tmp_path / "out" / "cmp.png"
    assert main(["compare", str(res), str(ref), "--plot", str(png)]) == 1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert f"figure:    {png}" in capsys.readouterr().out


@pytest.mark.parametrize("target, message", [
    ("dir", "unknown figure type ''"),
    ("cmp.csv", "unknown figure type '.csv'"),
    ("blocker/cmp.png", "is not a folder"),
])
def test_bad_plot_target_exit_2_before_comparing(target: str, message: str, tmp_path: Path,
                                                 ref: Path, capsys) -> None:
    (tmp_path / "dir").mkdir()
    (tmp_path / "blocker").write_text("a file")
    assert main(["compare", str(ref), str(ref), "--plot", str(tmp_path / target)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing compared, no verdict printed
    assert captured.err.startswith(f"cosim compare: error: {tmp_path / target}: --plot")
    assert message in captured.err and captured.err.count("\n") == 1


def test_plot_target_that_is_a_folder_named_like_a_figure(tmp_path: Path, ref: Path,
                                                          capsys) -> None:
    (tmp_path / "fig.png").mkdir()
    assert main(["compare", str(ref), str(ref), "--plot", str(tmp_path / "fig.png")]) == 2
    assert "--plot must name a file, but this is a folder" in capsys.readouterr().err


def test_tolerance_for_a_signal_that_is_not_compared_exit_2(tmp_path: Path, ref: Path,
                                                             capsys) -> None:
    """A per-signal --atol/--rtol must name a compared signal (it was silently ignored)."""
    res = write(tmp_path / "res.csv", T, {"h1": step(100) + 1e-3, "qa": 1e-4 * step(200)})
    assert main(["compare", str(res), str(ref), "--atol", "1e-9,h3=2e-3"]) == 2
    assert capsys.readouterr().err == ("cosim compare: error: --atol h3=0.002: 'h3' is not a "
                                       "compared signal (compared: 'h1', 'qa')\n")
    # in the files but not among the --signals compared
    assert main(["compare", str(res), str(ref), "--signals", "qa", "--rtol", "h1=1"]) == 2
    assert capsys.readouterr().err == ("cosim compare: error: --rtol h1=1: 'h1' is not a "
                                       "compared signal (compared: 'qa')\n")
    with pytest.raises(CosimError, match=r"'H1' is not a compared signal"):
        compare(res, ref, atol={"H1": 1.0})
    with pytest.raises(SystemExit) as info:  # an argparse usage error
        main(["compare", str(res), str(ref), "--atol", "=1"])
    assert info.value.code == 2
    assert "argument --atol: '=1': no signal name before '='" in capsys.readouterr().err


def test_help_example_tolerance_names_real_result_columns(tmp_path: Path, capsys) -> None:
    """The --help example (plant.h1=...) works on real result files; a bare h1 is refused
    with a hint."""
    reference = Path(__file__).resolve().parents[3] / "scenarios" / "references" \
        / "leak_tank1__pi.csv"
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = capsys.readouterr().out
    assert "--atol 1e-9,plant.h1=1e-4,plant.h2=1e-4" in text and "h1=1e-3" not in text
    assert main(["compare", str(reference), str(reference), "--quiet",
                 "--atol", "1e-9,plant.h1=1e-4,plant.h2=1e-4"]) == 0
    assert main(["compare", str(reference), str(reference), "--atol", "h1=1e-3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cosim compare: error: --atol h1=0.001: 'h1' is not a compared "
                          "signal (compared: 'ref.h1', ")
    assert err.endswith("; did you mean 'ref.h1' or 'plant.h1'?\n")
