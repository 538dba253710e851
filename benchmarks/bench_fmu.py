"""Benchmark: plant FMU doStep calls per second through fmpy.

Run on demand (not a test)::

    .venv/bin/python benchmarks/bench_fmu.py [--steps N] [--seed S]

Prints, for the FMI 2 and FMI 3 Co-Simulation FMUs, the rate of

* ``doStep`` alone (25 s communication step, pumps changing every 10 steps), and
* a full co-simulation step (set qa, qb; doStep; get h1..h4),

and ratios against baselines measured in the same run on the same input sequence:

* scipy ``solve_ivp`` (DOP853, rtol 1e-10) of the same ODE over one 25 s step (the obvious
  Python alternative to the FMU at the same accuracy): ratio > 1 means the FMU is faster;
* a bare ``fmi2GetReal`` of four values through fmpy (the cost of crossing into the FMU at
  all): the ratio says how many such calls one doStep costs.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "fmus"))

from fourtank_reference import QA_MAX, QB_MAX, rhs  # noqa: E402
from fourtank_run import LEVELS, Plant  # noqa: E402

from cosim.core.build import build_fmus  # noqa: E402

TS = 25.0


def _inputs(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    levels = rng.uniform(0.0, 1.0, size=(math.ceil(n / 10), 2)) * (QA_MAX, QB_MAX)
    return np.repeat(levels, 10, axis=0)[:n]


def bench_fmu(path: Path, u: np.ndarray) -> tuple[float, float, float]:
    """Return (doStep/s, full steps/s, getReal/s) for one FMU."""
    plant = Plant(path, "cs")
    try:
        plant.initialize()
        fmu, vr_in = plant.fmu, [plant.vr["qa"], plant.vr["qb"]]
        vr_out = [plant.vr[name] for name in LEVELS]
        setter = fmu.setReal if plant.version == 2 else fmu.setFloat64
        getter = fmu.getReal if plant.version == 2 else fmu.getFloat64
        n = len(u)

        t = 0.0
        start = time.perf_counter()
        for k in range(n):
            if k % 10 == 0:
                setter(vr_in, list(u[k]))
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=TS)
            t += TS
        do_step_rate = n / (time.perf_counter() - start)

        start = time.perf_counter()
        for k in range(n):
            setter(vr_in, list(u[k]))
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=TS)
            getter(vr_out)
            t += TS
        full_rate = n / (time.perf_counter() - start)

        start = time.perf_counter()
        for _ in range(n):
            getter(vr_out)
        get_rate = n / (time.perf_counter() - start)
    finally:
        plant.close()
    return do_step_rate, full_rate, get_rate


def bench_scipy(u: np.ndarray) -> float:
    """solve_ivp steps per second on the same inputs (DOP853, rtol 1e-10)."""
    from scipy.integrate import solve_ivp

    h = np.array([0.65, 0.65, 0.6514031296511584, 0.6638294000727866])
    start = time.perf_counter()
    for qa, qb in u:
        sol = solve_ivp(
            lambda _t, y, qa=qa, qb=qb: rhs(y, qa, qb),
            (0.0, TS),
            h,
            method="DOP853",
            rtol=1e-10,
            atol=1e-14,
        )
        h = np.maximum(sol.y[:, -1], 0.0)
    return len(u) / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="doSteps per measurement")
    parser.add_argument("--seed", type=int, default=0, help="seed of the input sequence")
    args = parser.parse_args(argv)

    fmu2, fmu3 = build_fmus()
    u = _inputs(args.steps, args.seed)
    n_scipy = max(200, args.steps // 50)
    scipy_rate = bench_scipy(u[:n_scipy])
    print(f"baseline scipy solve_ivp (DOP853, rtol 1e-10): {scipy_rate:12,.0f} steps/s")
    for label, path in (("FMI 2", fmu2), ("FMI 3", fmu3)):
        do_step, full, get = bench_fmu(path, u)
        print(f"{label} doStep through fmpy:              {do_step:12,.0f} calls/s")
        print(f"{label} set + doStep + get:               {full:12,.0f} steps/s")
        print(f"{label} baseline getReal(4 values):       {get:12,.0f} calls/s")
        print(f"  ratio doStep / scipy solve_ivp step:    {do_step / scipy_rate:12.1f}x faster")
        print(f"  ratio doStep cost / getReal cost:       {get / do_step:12.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
