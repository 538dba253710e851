"""``cosim run`` left alone: signals, hung and dying plants, full disks, shared folders.

Every test runs the real command line in its own process (``python -m cosim.cli run``) on real
FMUs: the project's C four-tank, or hostile pythonfmu plants from :mod:`pyfmu_models` that
hang in Python or in native code, crash, exit or return NaN. ``TMPDIR`` points into the test's
folder, so that FMU folders left behind (``cosim-fmu-*``) are seen.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.core.compare import read_table
from tests.cosim import pyfmu_models

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
#: 1000 steps of 25 s.
LONG = "time,ref.h1,ref.h2\n0,0.6,0.6\n5000,0.7,\n25000,,\n"
#: The hostile single-tank FMUs of pyfmu_models (pump a fills h1, pump b fills h2).
TANKS = ("Slow.fmu", "Hang.fmu", "NativeHang.fmu", "Segfault.fmu", "Exits.fmu", "Nan.fmu")
#: 80 steps.
SHORT = pyfmu_models.SHORT_SCENARIO


def scenario(tmp_path: Path, text: str = LONG, name: str = "sc.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def env_for(tmp_path: Path) -> dict[str, str]:
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    paths = [str(ROOT), os.environ.get("PYTHONPATH", "")]
    return dict(os.environ, TMPDIR=str(tmp), PYTHONPATH=os.pathsep.join(p for p in paths if p))


def leftovers(tmp_path: Path) -> list[str]:
    return sorted(p.name for p in (tmp_path / "tmp").glob("cosim-fmu-*"))


def command(*args: str | Path) -> list[str]:
    args = tuple(map(str, args))
    if "pi" in args and any(a.endswith(TANKS) for a in args):
        args += ("--option", "pairing=diagonal")  # one tank per pump in the test FMUs
    return [sys.executable, "-m", "cosim.cli", "run", *args, "--quiet"]


def start(tmp_path: Path, *args: str | Path, **kwargs: object) -> subprocess.Popen:
    return subprocess.Popen(command(*args), env=env_for(tmp_path), cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


def run(tmp_path: Path, *args: str | Path, timeout: float = 120,
        **kwargs: object) -> subprocess.CompletedProcess:
    return subprocess.run(command(*args), env=env_for(tmp_path), cwd=ROOT, text=True,
                          capture_output=True, timeout=timeout, check=False, **kwargs)


def data_rows(path: Path) -> int:
    """Complete data lines of a streamed CSV (0 while it does not exist)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return 0
    return max(0, text.count("\n") - 1)


def wait_for_rows(path: Path, n: int, proc: subprocess.Popen, timeout: float = 60) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        rows = data_rows(path)
        if rows >= n:
            return rows
        if proc.poll() is not None:
            pytest.fail(f"the run ended early ({proc.returncode}): {proc.communicate()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"{path}: fewer than {n} rows after {timeout} s")


def finish(proc: subprocess.Popen, timeout: float = 60) -> tuple[int, str]:
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(f"the run did not stop within {timeout} s")
    return proc.returncode, err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT],
                         ids=lambda s: s.name)
def test_signal_keeps_rows_and_writes_the_summary(sig: signal.Signals, tmp_path: Path,
                                                  pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    proc = start(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / "Slow.fmu",
                 "--controller", "pi", "--out", out)
    wait_for_rows(out / "results.csv.part", 20, proc)
    proc.send_signal(sig)
    code, err = finish(proc)
    assert code == 128 + sig, err
    assert one_line(err) == f"cosim run: interrupted ({sig.name})"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and sig.name in summary["reason"]
    assert 20 <= summary["steps"] < summary["steps_planned"] == 1000
    table = read_table(out / "results.csv")
    # every sample recorded up to the plant's last step: its own row too, unless the signal
    # came between that step and the row (measuring, or the controller's step: rare, seen
    # once in a full CI run)
    assert len(table.time) in (summary["steps"] + 1, summary["steps"])
    assert table.time[-1] == pytest.approx(25.0 * (len(table.time) - 1))   # every sample
    assert not (out / "results.csv.part").exists() and (out / "figure.png").is_file()


@pytest.mark.slow
def test_ctrl_c_inside_a_python_fmu_dostep_is_interrupted_not_failed(
        tmp_path: Path, pyfmu_dir: Path) -> None:
    # from t = 500 s the FMU spins in its own (Python) doStep: Ctrl-C lands inside it, and
    # pythonfmu turns the KeyboardInterrupt into an FMU error
    out = tmp_path / "out"
    proc = start(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / "Hang.fmu",
                 "--controller", "pi", "--out", out)
    wait_for_rows(out / "results.csv.part", 1, proc)
    time.sleep(1.5)
    proc.send_signal(signal.SIGINT)
    code, err = finish(proc)
    assert code == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted", summary["reason"]
    assert read_table(out / "results.csv").time[-1] == 500.0


@pytest.mark.slow
def test_sigkill_leaves_the_streamed_rows_and_the_previous_results(
        tmp_path: Path, pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    first = run(tmp_path, scenario(tmp_path, SHORT, "short.csv"), "--controller", "pi",
                "--out", out)
    assert first.returncode == 0, first.stderr
    previous = {n: (out / n).read_bytes() for n in ("results.csv", "summary.json")}
    proc = start(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / "Slow.fmu",
                 "--controller", "pi", "--out", out)
    part = out / "results.csv.part"
    before = wait_for_rows(part, 10, proc)
    time.sleep(2.5)
    during = data_rows(part)
    assert during > before  # flushed while the run goes (at least once a second)
    proc.kill()
    proc.communicate()
    table = read_table(part)  # a readable CSV, every line complete
    assert len(table.time) >= during and table.time[0] == 0.0
    assert list(table.time) == [25.0 * k for k in range(len(table.time))]
    assert {n: (out / n).read_bytes() for n in previous} == previous


@pytest.mark.slow
@pytest.mark.parametrize("fmu", ["NativeHang", "Hang"])
def test_step_timeout_stops_a_hung_plant(fmu: str, tmp_path: Path, pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    t0 = time.monotonic()
    proc = run(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / f"{fmu}.fmu",
               "--controller", "pi", "--out", out, "--step-timeout", "2")
    assert time.monotonic() - t0 < 60
    assert proc.returncode == 1, proc.stderr
    line = one_line(proc.stderr)
    assert "doStep at t=500.0 took longer than the step timeout of 2 s (worker killed)" in line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "step timeout of 2 s" in summary["reason"]
    assert summary["isolated"] is True and summary["step_timeout"] == 2.0
    assert read_table(out / "results.csv").time[-1] == 500.0
    assert leftovers(tmp_path) == []


@pytest.mark.slow
def test_step_timeout_stops_a_hung_controller(tmp_path: Path, fmu2_path: Path) -> None:
    out = tmp_path / "out"
    proc = run(tmp_path, scenario(tmp_path, SHORT), "--plant", fmu2_path,
               "--controller", "tests.cosim.sleepy:SleepyPI", "--option", "hang_at=100",
               "--out", out, "--step-timeout", "1")
    assert proc.returncode == 1, proc.stderr
    assert ("controller 'pi': step at t=100.0 took longer than the step timeout of 1 s"
            in one_line(proc.stderr))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["steps"] == 4
    assert read_table(out / "results.csv").time[-1] == 75.0


@pytest.mark.slow
def test_one_ctrl_c_stops_a_hung_isolated_worker_at_once(tmp_path: Path,
                                                          pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    proc = start(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / "NativeHang.fmu",
                 "--controller", "pi", "--out", out, "--isolate")
    wait_for_rows(out / "results.csv.part", 1, proc)
    time.sleep(2.0)  # the worker is stuck in native code at t = 500 s
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    code, err = finish(proc, timeout=30)
    assert time.monotonic() - t0 < 15
    assert code == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] == 20
    assert leftovers(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize(("fmu", "why"), [("Segfault", "worker died (signal 11, SIGSEGV)"),
                                          ("Exits", "worker died (exit code 3)")])
def test_a_dying_worker_leaves_no_fmu_folder(fmu: str, why: str, tmp_path: Path,
                                             pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    proc = run(tmp_path, scenario(tmp_path, SHORT), "--plant",
               pyfmu_dir / f"{fmu}.fmu", "--controller", "pi", "--out", out, "--isolate")
    assert proc.returncode == 1, proc.stderr
    assert f"doStep at t=500.0 failed: {why}" in one_line(proc.stderr)
    assert read_table(out / "results.csv").time[-1] == 500.0
    assert leftovers(tmp_path) == []


@pytest.mark.slow
def test_nan_output_fails_naming_the_output(tmp_path: Path, pyfmu_dir: Path) -> None:
    out = tmp_path / "out"
    proc = run(tmp_path, scenario(tmp_path, SHORT), "--plant", pyfmu_dir / "Nan.fmu",
               "--controller", "pi", "--out", out)
    assert proc.returncode == 1, proc.stderr
    assert "plant output 'h1' is nan at t=525.0" in one_line(proc.stderr)
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"


def _limit_file_size(limit: int) -> None:  # runs in the child before exec
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


@pytest.mark.slow
def test_full_disk_is_one_line_and_keeps_the_previous_files(tmp_path: Path,
                                                            fmu2_path: Path) -> None:
    out = tmp_path / "out"
    sc = ROOT / "scenarios" / "paper_steps.csv"
    first = run(tmp_path, sc, "--plant", fmu2_path, "--controller", "pi", "--out", out)
    assert first.returncode == 0, first.stderr
    previous = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(previous) == {"results.csv", "summary.json", "figure.png", "controller.json"}
    # results.csv is ~300 kB: writes past 100 kB fail with EFBIG, like a full disk
    proc = run(tmp_path, sc, "--plant", fmu2_path, "--controller", "pi", "--out", out,
               preexec_fn=lambda: _limit_file_size(100_000))
    assert proc.returncode == 1, proc.stderr
    line = one_line(proc.stderr)
    assert f"{out / 'results.csv'}: cannot write: File too large" in line
    assert {n: (out / n).read_bytes() for n in previous} == previous
    kept = read_table(out / "results.csv.part")  # the rows up to the fault, complete lines
    assert 0 < len(kept.time) < 1601
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files


def test_unwritable_out_is_one_line_exit_1(tmp_path: Path, fmu2_path: Path) -> None:
    if not Path("/proc/self").is_dir():
        pytest.skip("needs /proc")
    proc = run(tmp_path, scenario(tmp_path, SHORT), "--plant", fmu2_path,
               "--controller", "pi", "--out", "/proc/cosim-out")
    assert proc.returncode == 1, proc.stderr
    assert "/proc/cosim-out" in one_line(proc.stderr)


@pytest.mark.slow
def test_second_run_into_the_same_folder_is_refused(tmp_path: Path, pyfmu_dir: Path,
                                                    fmu2_path: Path) -> None:
    out = tmp_path / "out"
    proc = start(tmp_path, scenario(tmp_path), "--plant", pyfmu_dir / "Slow.fmu",
                 "--controller", "pi", "--out", out)
    wait_for_rows(out / "results.csv.part", 1, proc)
    second = run(tmp_path, scenario(tmp_path, SHORT, "short.csv"), "--plant", fmu2_path,
                 "--controller", "pi", "--out", out)
    assert second.returncode == 2
    assert one_line(second.stderr) == (
        f"cosim run: error: {out}: another cosim run is writing into this folder (--out); "
        "wait for it to end or choose another folder")
    proc.send_signal(signal.SIGTERM)
    code, err = finish(proc)
    assert code == 143, err
    assert json.loads((out / "summary.json").read_text())["scenario"].endswith("sc.csv")


@pytest.mark.slow
def test_rerun_leaves_no_file_of_the_previous_run(tmp_path: Path, fmu2_path: Path) -> None:
    out = tmp_path / "out"
    sc = scenario(tmp_path, SHORT)
    first = run(tmp_path, sc, "--plant", fmu2_path, "--controller", "tests.cosim.sleepy:TimedPI",
                "--out", out)
    assert first.returncode == 0, first.stderr
    assert {p.name for p in out.iterdir()} == {"results.csv", "summary.json", "figure.png",
                                               "timings.csv", "controller.json"}
    second = run(tmp_path, sc, "--plant", fmu2_path, "--controller", "pi", "--out", out,
                 "--no-figure")
    assert second.returncode == 0, second.stderr
    assert {p.name for p in out.iterdir()} == {"results.csv", "summary.json", "controller.json"}
    assert json.loads((out / "summary.json").read_text())["controller"] == "pi"
    assert json.loads((out / "controller.json").read_text())["controller"] == "pi"


def test_default_plant_does_not_depend_on_the_current_folder(tmp_path: Path,
                                                             fmu2_path: Path) -> None:
    proc = subprocess.run(
        command(scenario(tmp_path, SHORT), "--controller", "pi", "--out", tmp_path / "out",
                "--no-figure"),
        env=env_for(tmp_path), cwd=tmp_path, text=True, capture_output=True, timeout=120,
        check=False)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert Path(summary["plant"]) == fmu2_path.resolve()
