"""The regression check is strict enough: deliberate small changes fail with a readable report,
and an unchanged setting reproduces its results exactly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cosim.core.compare import compare, read_table
from tests.regression import regression_cases as rc

HERE = Path(__file__).parent
#: A short scenario (80 steps of 25 s) with a set-point step on each output.
SHORT = """time,ref.h1,ref.h2
0,0.65,0.65
250,0.75,
1000,,0.72
2000,,
"""
#: Perturbed controller (``regression_perturbed:<Class>``) -> the controller it perturbs.
PERTURBED = {
    "tests.regression.regression_perturbed:PIGainUp": "pi",                  # PI gains ×1.1
    "tests.regression.regression_perturbed:MPCInputWeight": "robust-mpc",    # R = 0.01 I -> 0.011 I
    "tests.regression.regression_perturbed:MPCModelWeight": "robust-mpc",    # U_o[0][0] + 1e-3
}


@pytest.fixture(scope="module")
def short_runs(tmp_path_factory: pytest.TempPathFactory,
               plant_fmus: dict[str | None, Path]) -> dict[str, rc.Run]:
    """The short scenario with each baseline (twice) and each perturbed controller."""
    root = tmp_path_factory.mktemp("sensitivity")
    scenario = root / "short.csv"
    scenario.write_text(SHORT)
    names = ["pi", "robust-mpc", *PERTURBED]
    cases = [rc.Case(scenario, n, options=rc.recording_options(n, PERTURBED.get(n)))
             for n in names if rc.controller_available(PERTURBED.get(n, n)) is None]
    runs = {}
    for repeat in ("a", "b"):
        batch = [c for c in cases if repeat == "a" or ":" not in c.controller]
        for key, run in rc.run_cases(batch, root / repeat, plant_fmus, workers=2,
                                     ).items():
            runs[f"{key}#{repeat}"] = run
    return runs


def _run(runs: dict[str, rc.Run], controller: str, repeat: str = "a") -> rc.Run:
    key = f"short__{controller}#{repeat}"
    if key not in runs:
        base = PERTURBED.get(controller, controller)
        pytest.skip(f"controller '{base}' not available: {rc.controller_available(base)}")
    run = runs[key]
    assert run.returncode == 0, f"cosim run --controller {controller} failed:\n{run.output}"
    return run


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["pi", "robust-mpc"])
def test_same_run_twice_gives_identical_csv(short_runs: dict[str, rc.Run],
                                            controller: str) -> None:
    first = _run(short_runs, controller, "a").results.read_bytes()
    second = _run(short_runs, controller, "b").results.read_bytes()
    # wall-clock solve times go to timings.csv; results.csv must match byte for byte
    assert first == second, f"two {controller} runs of the same scenario wrote different results"


@pytest.mark.slow
@pytest.mark.parametrize("controller", list(PERTURBED), ids=[k.split(":")[1] for k in PERTURBED])
def test_small_change_fails_with_readable_report(short_runs: dict[str, rc.Run], controller: str,
                                                 tmp_path: Path) -> None:
    baseline = _run(short_runs, PERTURBED[controller])
    changed = _run(short_runs, controller)
    signals = rc.compared_columns(read_table(baseline.results).names)
    result = compare(changed.results, baseline.results, signals=signals)
    assert not result.passed, f"{controller} was not detected:\n{result.report()}"
    failing = {s.name for s in result.failed}
    assert failing & {"ctrl.qa", "ctrl.qb"}, failing
    report = result.report()
    assert "FAIL ctrl.q" in report and "worst at t = " in report
    assert report.splitlines()[-1].startswith("FAIL: ")
    # The same through the command line: exit 1 and the report on stdout.
    proc = subprocess.run(
        [sys.executable, "-m", "cosim.cli", "compare", str(changed.results),
         str(baseline.results), "--signals", ",".join(signals), "--plot",
         str(tmp_path / "diff.png")],
        capture_output=True, text=True, check=False)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "FAIL" in proc.stdout and (tmp_path / "diff.png").stat().st_size > 0
