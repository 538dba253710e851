"""Master overhead: a closed-loop run vs a bare fmpy doStep loop, in the same process.

Both loops run the same FMU (Co-Simulation) for the same number of 25 s steps:

* baseline: fmpy ``FMU2Slave`` with ``setReal(qa, qb)``, ``doStep``, ``getReal(h1..h4)``,
  and the same PI controller called directly (plain Python, no master);
* master: :class:`cosim.core.master.Master` with :class:`cosim.core.fmu.FmuComponent` and the PI
  controller, recording every signal (results are not written to disk).

Both are timed from the first step to the last (FMU extraction and loading excluded).

Prints the median time per step of each and their ratio (target ≤ 1.3x).

Usage: ``python benchmarks/bench_master.py [--steps N] [--repeats R] [--fmu PATH]``
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.adapters.pi import PIController  # noqa: E402
from cosim.core.fmu import FmuComponent  # noqa: E402
from cosim.core.master import Master  # noqa: E402
from cosim.core.scenario import load  # noqa: E402


def bare_loop(fmu_path: Path, steps: int, dt: float, with_pi: bool = True) -> float:
    """Seconds for ``steps`` doSteps through fmpy directly (PI in the loop unless not asked)."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave

    md = fmpy.read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = tempfile.mkdtemp()
    try:
        fmpy.extract(str(fmu_path), unzip)
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bare")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        pi = PIController()
        vin = [vr["qa"], vr["qb"]]
        vout = [vr["h1"], vr["h2"], vr["h3"], vr["h4"]]
        ref = {"ref.h1": 0.9, "ref.h2": 0.8}
        t = 0.0
        t0 = time.perf_counter()
        for _ in range(steps):
            h = fmu.getReal(vout)
            if with_pi:
                pi.set_inputs({"h1": h[0], "h2": h[1], **ref})
                pi.step(t, dt)
                u = pi.get_outputs()
                fmu.setReal(vin, [u["qa"], u["qb"]])
            else:
                fmu.setReal(vin, [4.5e-4, 5.5e-4])
            fmu.doStep(t, dt)
            t += dt
        elapsed = time.perf_counter() - t0
        fmu.terminate()
        fmu.freeInstance()
    finally:
        shutil.rmtree(unzip, ignore_errors=True)
    return elapsed


def master_loop(fmu_path: Path, steps: int, dt: float, scenario: Path) -> float:
    """Seconds for the same number of steps through the master."""
    master = Master(FmuComponent(fmu_path), PIController(), load(scenario))
    result = master.run()
    assert result.status == "ok" and result.steps == steps, result.reason
    return result.loop_time_s


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--fmu", type=Path, default=ROOT / "fmus" / "FourTank.fmu")
    args = parser.parse_args()
    if not args.fmu.is_file():
        from cosim.core.build import build_fmus

        build_fmus()
    dt = 25.0
    with tempfile.TemporaryDirectory() as tmp:
        scenario = Path(tmp) / "bench.csv"
        scenario.write_text(f"time,ref.h1,ref.h2\n0,0.9,0.8\n{args.steps * dt},,\n")
        bare, master, fmu_only = [], [], []
        for _ in range(args.repeats):  # interleaved, so drifts hit both alike
            fmu_only.append(bare_loop(args.fmu, args.steps, dt, with_pi=False))
            bare.append(bare_loop(args.fmu, args.steps, dt))
            master.append(master_loop(args.fmu, args.steps, dt, scenario))
    b, m = statistics.median(bare), statistics.median(master)
    ratio = m / b
    f = statistics.median(fmu_only)
    print(f"bare fmpy loop      : {1e6 * f / args.steps:8.2f} us/step (no controller)")
    print(f"bare fmpy loop + PI : {1e6 * b / args.steps:8.2f} us/step (median of {args.repeats})")
    print(f"master + PI         : {1e6 * m / args.steps:8.2f} us/step")
    print(f"ratio master / bare : {ratio:8.3f}x  (target <= 1.3x) "
          f"{'OK' if ratio <= 1.3 else 'ABOVE TARGET'}")
    print(f"ratio master / bare loop without controller: {m / f:.3f}x (for information)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
