"""A rehearsal on a virtual plant: the robust MPC over OPC UA against ``cosim serve-plant``.

    python examples/live_rehearsal.py [--out DIR] [--speed K]

Starts ``cosim serve-plant`` (the four-tank FMU as an OPC UA server on 127.0.0.1, K times
faster than real time, frozen until the controller's first write), runs the robust MPC
against it through the Python API on the wall clock (``plant="opc.tcp://..."``), then the
same scenario with the FMU in-process, and prints the live loop's figures (fresh samples,
deadline misses, loop latency) and how far the two closed loops are apart (nothing, at a
speed without a deadline miss). The run's files go under ``DIR`` (default: a temporary
folder); the server is stopped however the script ends. Docs: "Run on a live process".
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np

import cosim
from cosim.live.process import served_plant
from cosim.live.runner import LiveOptions

ROOT = Path(__file__).resolve().parents[1]
#: The paper's first set-point steps, 60 samples of 25 s.
SCENARIO = "time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n1000,,1.0\n1500,,\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--speed", type=float, default=250.0,
                        help="the plant's speed-up (default 250: a sample every 0.1 s)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="live-rehearsal-"))
    out.mkdir(parents=True, exist_ok=True)
    scenario = out / "steps.csv"
    scenario.write_text(SCENARIO)
    with served_plant("--speed", str(args.speed), "--frozen", "--security", "None",
                      "--record", str(out / "plant.csv"), log=out / "serve-plant.log",
                      env=dict(os.environ, PYTHONPATH=str(ROOT))) as plant:
        live = cosim.run(scenario, plant=plant.endpoint, out=out / "live",
                         live=LiveOptions(speed=args.speed), on_notice=print)
    ref = cosim.run(scenario, out=out / "in-process")
    lv = live.summary["live"]
    loop = lv["latency_ms"]["loop"]
    print(f"live run: status {live.status}, {lv['fresh']} of {lv['samples']} samples fresh, "
          f"{lv['deadline_misses']} deadline misses, loop median {loop['median']:.2f} ms, "
          f"p99 {loop['p99']:.2f} ms (a sample every {1e3 * lv['period_s']:.0f} ms)")
    a, b = live.to_pandas(), ref.to_pandas()
    for col, span in (("plant.h1", 2.0), ("plant.h2", 2.0), ("ctrl.qa", 9.05e-4),
                      ("ctrl.qb", 11.1e-4)):
        gap = float(np.max(np.abs(a[col].to_numpy() - b[col].to_numpy()))) / span
        print(f"  {col:9s} live vs in-process: {gap:.1e} of its range")
    print(f"files in {out}")


if __name__ == "__main__":
    main()
