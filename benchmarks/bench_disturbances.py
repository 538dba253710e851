"""The robust MPC's step with measured disturbances and dead time against the same state size
without (issue 46; aim: at most 1.2×).

Two random δISS GRUs of the same size (``n`` states, two inputs, two outputs, the seed's
weights): the plain one, and one whose inputs also take a measured disturbance and act
``--delay`` samples late. Each runs the robust MPC (tracking law, compiled kernel) in closed
loop with itself as the plant (``GRUPlant``: the disturbance set from the scenario, the dead
time applied), on set-point steps and, for the second, disturbance steps; the rounds alternate
the two so that the machine's load hits both alike. Printed: the controller step's median and
p99 (wall clock) of each, and their ratios.

Usage::

    .venv/bin/python benchmarks/bench_disturbances.py [--rounds 3] [--n 20] [--delay 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.model import GRUModel  # noqa: E402
from controllers.problem import Channel, ControlProblem  # noqa: E402

#: Set-point steps (both models) and disturbance steps (the second), 60 samples each.
STEPS = ((0.2, -0.1, 0.0), (-0.3, 0.2, 0.6), (0.1, 0.3, -0.5), (-0.1, -0.2, 0.2))
HOLD = 60


def problem(disturbed: bool, delay: int) -> ControlProblem:
    """A 2 × 2 problem, with a measured disturbance and dead time when ``disturbed``."""
    ins = tuple(Channel(f"u{j}", "1", -1.0, 1.0, delay=delay if disturbed else 0)
                for j in (1, 2))
    outs = tuple(Channel(f"y{j}", "1", -1.0, 1.0) for j in (1, 2))
    dist = (Channel("d", "1", -1.0, 1.0, rate=0.05),) if disturbed else ()
    return ControlProblem(name="bench", Ts=1.0, inputs=ins, outputs=outs, disturbances=dist)


def model(disturbed: bool, n: int, delay: int, seed: int) -> GRUModel:
    """A small-weight δISS GRU (ν < 1) for :func:`problem`; the same weights of the inputs,
    states and outputs for both, the disturbance's column added to the second."""
    pr = problem(disturbed, delay)
    rng = np.random.default_rng(seed)

    def mat(rows: int, cols: int, row_sum: float) -> np.ndarray:
        a = rng.uniform(-1.0, 1.0, (rows, cols))
        return a * (row_sum / np.abs(a).sum(axis=1, keepdims=True))

    params = {"W_z": mat(n, 3, 0.1), "U_z": mat(n, n, 0.05), "b_z": rng.uniform(1.9, 2.1, n),
              "W_r": mat(n, 3, 0.3), "U_r": mat(n, n, 0.3), "b_r": rng.uniform(-0.2, 0.2, n),
              "W_h": mat(n, 3, 1.2), "U_h": mat(n, n, 0.6), "b_h": rng.uniform(-0.1, 0.1, n),
              "U_o": mat(2, n, 1.5), "b_o": np.zeros(2)}
    if not disturbed:
        for w in ("W_z", "W_r", "W_h"):
            params[w] = params[w][:, :2]
    norm = pr.normalization()
    return GRUModel(params=params, u_offset=norm["u_offset"], u_scale=norm["u_scale"],
                    y_offset=norm["y_offset"], y_scale=norm["y_scale"],
                    input_names=list(pr.model_input_names),
                    input_units=[c.unit for c in pr.model_inputs],
                    output_names=list(pr.output_names), output_units=list(pr.output_units),
                    Ts=pr.Ts, w_y_bar=0.002, training={"source": "bench_disturbances"},
                    problem=pr)


def scenario(path: Path, disturbed: bool) -> Path:
    lines = ["time,ref.y1,ref.y2" + (",dist.d" if disturbed else "")]
    for k, (a, b, d) in enumerate(STEPS):
        lines.append(f"{k * HOLD},{a},{b}" + (f",{d}" if disturbed else ""))
    lines.append(f"{len(STEPS) * HOLD},,," if disturbed else f"{len(STEPS) * HOLD},,")
    path.write_text("\n".join(lines) + "\n")
    return path


def closed_loop(model_path: Path, scenario_path: Path) -> list[float]:
    """The controller step times [ms] of one closed-loop run."""
    from cosim.adapters.gru_plant import GRUPlant
    from cosim.adapters.robust_mpc import RobustMPCController
    from cosim.core import scenario as scenarios
    from cosim.core.master import Master

    ctrl = RobustMPCController(model=model_path)
    times: list[float] = []
    step = ctrl.step

    def timed(t: float, dt: float) -> None:
        t0 = time.perf_counter()
        step(t, dt)
        times.append((time.perf_counter() - t0) * 1e3)

    ctrl.step = timed  # type: ignore[method-assign]
    plant = GRUPlant(GRUModel.load(model_path))
    result = Master(plant, ctrl, scenarios.load(scenario_path)).run()
    if result.status != "ok":
        raise SystemExit(f"bench_disturbances: the run failed: {result.reason}")
    if ctrl.mpc.fhocp.kernel is None:
        raise SystemExit("bench_disturbances: no compiled kernel (gcc?)")
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--n", type=int, default=20, help="states (default 20)")
    parser.add_argument("--delay", type=int, default=2, help="dead time [samples] (2)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-dist-") as tmp:
        files = {}
        for label, disturbed in (("plain", False), ("disturbance + dead time", True)):
            path = Path(tmp) / f"{disturbed}.json"
            model(disturbed, args.n, args.delay, args.seed).save(path)
            files[label] = (path, scenario(Path(tmp) / f"{disturbed}.csv", disturbed))
        times: dict[str, list[float]] = {k: [] for k in files}
        for _ in range(args.rounds):
            for label, (m, sc) in files.items():
                times[label] += closed_loop(m, sc)
    print(f"robust MPC step, n = {args.n}, 2 inputs, 2 outputs, N = default, "
          f"{args.rounds} rounds of {len(STEPS) * HOLD} steps each (GRU plant)")
    stats = {k: (float(np.median(v)), float(np.percentile(v, 99))) for k, v in times.items()}
    for label, (med, p99) in stats.items():
        print(f"  {label:26s} median {med:6.3f} ms   p99 {p99:6.3f} ms")
    (m0, p0), (m1, p1) = stats["plain"], stats["disturbance + dead time"]
    print(f"  ratio (aim <= 1.2x)        median {m1 / m0:6.2f}x    p99 {p1 / p0:6.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
