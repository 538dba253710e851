"""The live loop's latency against a served plant, beside the controller step measured in the
same run, and the fastest plant it keeps up with (issue 47; issue 60, goal 7).

A real ``cosim serve-plant`` (the four-tank FMU, its own process, 127.0.0.1) at speed-up K,
and ``cosim run --plant opc.tcp://...`` with the robust MPC (tracking law, compiled kernel) on
the paper's first set-point steps. Printed, for each K tried (doubling from ``--speed`` to
``--max-speed``): the loop latency per sample (read -> compute -> write) median and p99, the
controller step alone (compute) median and p99, their ratio (loop over step: 1 would be a
loop that costs nothing but the step), deadline misses and stale samples; then the largest K
with 0 deadline misses and 0 stale samples on this machine. ``--busy`` keeps one core busy
with a second process (a Python busy loop) for the whole benchmark, as another program on a
plant's controller PC would. Printed, never asserted: a timed unit test on a shared machine
measures the machine.

Usage::

    .venv/bin/python benchmarks/bench_live.py [--samples 80] [--speed 250] [--max-speed 8000]
        [--busy]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
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
    if out.status not in ("ok", "degraded"):
        raise SystemExit(f"speed {speed:g}: the run failed: {out.reason}")
    return out.summary["live"]


@contextlib.contextmanager
def busy_core(on: bool) -> Iterator[None]:
    """A second process that keeps one core busy for the block (``on``), stopped after it."""
    if not on:
        yield
        return
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        proc.kill()
        proc.wait(10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=80, help="samples per run")
    parser.add_argument("--speed", type=float, default=250.0, help="first speed-up K")
    parser.add_argument("--max-speed", type=float, default=8000.0, help="last K tried")
    parser.add_argument("--busy", action="store_true",
                        help="keep one core busy with a second process meanwhile")
    args = parser.parse_args()
    print(f"live loop against cosim serve-plant (four-tank, robust MPC), {args.samples} "
          f"samples per run, {os.cpu_count()} CPUs"
          + (", one core kept busy by a second process" if args.busy else ""))
    print(f"{'K':>6} {'period':>9} {'loop median':>12} {'loop p99':>9} {'step median':>12} "
          f"{'step p99':>9} {'ratio':>6} {'misses':>6} {'stale':>5}")
    best, speed, clean = None, args.speed, True
    with tempfile.TemporaryDirectory() as tmp, busy_core(args.busy):
        while speed <= args.max_speed:
            lv = one(speed, args.samples, Path(tmp))
            loop, step = lv["latency_ms"]["loop"], lv["latency_ms"]["compute"]
            print(f"{speed:6g} {1e3 * TS / speed:7.1f}ms {loop['median']:10.2f}ms "
                  f"{loop['p99']:7.2f}ms {step['median']:10.2f}ms {step['p99']:7.2f}ms "
                  f"{loop['median'] / step['median']:5.2f}x {lv['deadline_misses']:6d} "
                  f"{lv['stale']:5d}", flush=True)
            clean = clean and not (lv["deadline_misses"] or lv["stale"])
            if clean:
                best = speed
            speed *= 2
    if best is None:
        print(f"largest speed-up with 0 deadline misses: none from K = {args.speed:g}")
    else:
        print(f"largest speed-up with 0 deadline misses (and every smaller one tried): K = "
              f"{best:g} (one sample every {1e3 * TS / best:.1f} ms)")


if __name__ == "__main__":
    main()
