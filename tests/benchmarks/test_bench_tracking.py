"""``benchmarks/bench_tracking.py``: the oracle NMPC's model, and the benchmark run ``--quick``
as a user runs it (its own process)."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks"


def _oracle_module() -> ModuleType:
    """``benchmarks/oracle_nmpc.py`` (the benchmarks folder is not a package)."""
    spec = importlib.util.spec_from_file_location("oracle_nmpc", BENCH / "oracle_nmpc.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it executes
    spec.loader.exec_module(module)
    return module


def test_oracle_model_holds_the_fmu_equilibrium(fmu2_path: Path) -> None:
    """The parameters read from the FMU give its default operating point: the steady-state
    inputs of h1 = h2 = 0.65 m are the FMU's start inputs, and one RK4 sample from the FMU's
    start levels stays there."""
    mod = _oracle_module()
    params = mod.FourTankParameters.from_fmu(fmu2_path)
    u = params.steady_inputs(0.65, 0.65)
    np.testing.assert_allclose(u, [4.5472443083696316e-4, 5.5233543431505480e-4], rtol=1e-12)
    h0 = np.array([0.65, 0.65, 0.6514031296511584, 0.6638294000727866])
    h1 = np.asarray(mod.rk4_map(params, 25.0, 5)(h0, u)).ravel()
    np.testing.assert_allclose(h1, h0, atol=1e-9)


@pytest.mark.slow
def test_quick_benchmark_oracle_tracks(tmp_path: Path) -> None:
    """``--quick``: all four run; the oracle solves every step, predicts the FMU to 1e-6 m,
    and its summed IAE is below the PI's (on the first 5000 s: 0.79×); the default robust
    MPC's (the tracking law) is below the paper law's."""
    proc = subprocess.run([sys.executable, str(BENCH / "bench_tracking.py"), "--quick",
                           "--out", str(tmp_path)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "MPC/oracle" in proc.stdout
    doc = json.loads((tmp_path / "tracking.json").read_text())
    kpis = doc["kpis"]
    assert set(kpis) == {"robust-mpc", "paper", "pi", "oracle"}
    assert "paper/PI" in proc.stdout
    assert kpis["robust-mpc"]["iae.sum"] < kpis["paper"]["iae.sum"]
    for row in kpis.values():
        assert all(math.isfinite(v) and v >= 0 for v in row.values()), row
    assert kpis["oracle"]["iae.sum"] < kpis["pi"]["iae.sum"]
    oracle = doc["controller_summary"]["oracle"]
    assert oracle["failures"] == 0
    assert oracle["prediction_error_max_m"] < 1e-6
    assert doc["controller_summary"]["robust-mpc"]["step_ms_median"] > 0
    assert (tmp_path / "tracking.png").stat().st_size > 0
