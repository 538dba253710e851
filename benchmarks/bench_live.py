"""The live loop's latency against a served plant, and the fastest plant it keeps up with
(issue 47).

A real ``cosim serve-plant`` (the four-tank FMU, its own process, 127.0.0.1) at speed-up K,
and ``cosim run --plant opc.tcp://...`` with the robust MPC (tracking law, compiled kernel) on
the paper's first set-point steps. Printed, for each K tried (doubling from ``--speed``):
the loop latency per sample (read -> compute -> write) median and p99, the controller step
alone (compute) median and p99, their ratio, deadline misses and stale samples; then the
largest K with 0 deadline misses and 0 stale samples on this machine.

Usage::

    .venv/bin/python benchmarks/bench_live.py [--samples 80] [--speed 250] [--max-speed 8000]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TS = 25.0     # the four-tank's sample time [s]


def one(speed: float, samples: int, folder: Path) -> dict:
    """One live run at ``speed``: its summary's ``live`` section."""
    import cosim
    from cosim.live.process import served_plant
    from cosim.live.runner import LiveOptions

    scenario = folder / "steps.csv"
    t1, t2 = TS * (samples // 3), TS * (2 * samples // 3)
    scenario.write_text(f"time,ref.h1,ref.h2\n0,0.65,0.65\n{t1:g},0.9,\n{t2:g},,1.0\n"
                        f"{TS * samples:g},,\n")
    with served_plant("--security", "None", "--speed", str(speed), "--frozen", "--quiet",
                      log=folder / f"serve_{speed:g}.log",
                      env=dict(os.environ, PYTHONPATH=str(ROOT))) as plant:
        out = cosim.run(scenario, plant=plant.endpoint, figure=False,
                        live=LiveOptions(speed=speed))
    if out.status != "ok":
        raise SystemExit(f"speed {speed:g}: the run failed: {out.reason}")
    return out.summary["live"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=80, help="samples per run")
    parser.add_argument("--speed", type=float, default=250.0, help="first speed-up K")
    parser.add_argument("--max-speed", type=float, default=8000.0, help="last K tried")
    args = parser.parse_args()
    print(f"live loop against cosim serve-plant (four-tank, robust MPC), {args.samples} "
          f"samples per run, {os.cpu_count()} CPUs")
    print(f"{'K':>6} {'period':>9} {'loop median':>12} {'loop p99':>9} {'step median':>12} "
          f"{'step p99':>9} {'ratio':>6} {'misses':>6} {'stale':>5}")
    best = None
    speed = args.speed
    with tempfile.TemporaryDirectory() as tmp:
        while speed <= args.max_speed:
            lv = one(speed, args.samples, Path(tmp))
            loop, step = lv["latency_ms"]["loop"], lv["latency_ms"]["compute"]
            print(f"{speed:6g} {1e3 * TS / speed:7.1f}ms {loop['median']:10.2f}ms "
                  f"{loop['p99']:7.2f}ms {step['median']:10.2f}ms {step['p99']:7.2f}ms "
                  f"{loop['median'] / step['median']:5.2f}x {lv['deadline_misses']:6d} "
                  f"{lv['stale']:5d}", flush=True)
            if lv["deadline_misses"] or lv["stale"]:
                break
            best = speed
            speed *= 2
    if best is None:
        print(f"largest speed-up with 0 deadline misses: none from K = {args.speed:g}")
    else:
        print(f"largest speed-up with 0 deadline misses: K = {best:g} (one sample every "
              f"{1e3 * TS / best:.1f} ms)" + (" (the last tried)" if speed > args.max_speed
                                               else ""))


if __name__ == "__main__":
    main()
