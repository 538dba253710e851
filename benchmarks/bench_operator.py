"""The robust MPC's step with an operator change at every step against the same step without
(issue 61, goal 3: re-deriving what the law needs between two steps costs at most twice the
step at the 99th percentile).

In one process, the shipped robust MPC (tracking law, its model as the plant: the GRU
simulated in numpy from the controller's first estimate, so that both loops see the same
plant) runs the same set-point steps twice, ``--steps`` samples each:

* ``baseline``: no operator setting at all (the controller's step as before issue 61);
* ``changes``: before every step one operator setting changes, in turn: an output limit
  narrowed and given back (``op.max.h1``: a ramp within the plan's room, ``Y_s`` narrowed),
  an input out of service and back (``op.service.qb``), an input limit (``op.min.qa``),
  each checked and re-derived by :meth:`controllers.mpc.RobustMPC.operate`.

The time of each step (the setting's :meth:`~controllers.mpc.RobustMPC.operate` and the
:meth:`~controllers.mpc.RobustMPC.step`, wall clock) is recorded; printed: median, p90, p99
and max of both loops, and the ratio of their p99s (the target: ≤ 2).

Usage::

    .venv/bin/python benchmarks/bench_operator.py [--steps 200] [--rounds 1]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from controllers import gru  # noqa: E402
from controllers.model import DEFAULT_MODEL, GRUModel  # noqa: E402
from controllers.mpc import RobustMPC  # noqa: E402
from controllers.mpc_options import MPCOptions  # noqa: E402

#: The changes of the ``changes`` loop, one before each step, in turn.
CHANGES = [("op.max.h1", 1.45), ("op.service.qb", 0.0), ("op.min.qa", 2e-4),
           ("op.max.h1", 2.0), ("op.service.qb", 1.0), ("op.min.qa", 0.0)]
#: The set-points (the problem's units), each held a quarter of the run.
SETPOINTS = [(0.8, 0.8), (1.0, 1.1), (0.7, 0.9), (0.9, 0.75)]


def closed_loop(mpc: RobustMPC, steps: int, changes: bool) -> np.ndarray:
    """Each step's wall time [ms] of a closed loop on the controller's own model."""
    mpc.reset()
    model = mpc.full_model
    x = None
    times = np.empty(steps)
    for k in range(steps):
        ref = np.array(SETPOINTS[min(4 * k // steps, 3)])
        if x is None:   # at rest at the first set-point's equilibrium
            from controllers.equilibrium import equilibrium_for_output

            x, _ = equilibrium_for_output(model.params, model.normalize_y(ref), None)
        y = model.denormalize_y(model.params["U_o"] @ x + model.params["b_o"])
        t0 = time.perf_counter()
        if changes:
            name, value = CHANGES[k % len(CHANGES)]
            with contextlib.suppress(ValueError):   # a refusal is a change too (kept)
                mpc.operate(name, value)
        step = mpc.step(y, ref, None, 25.0 * k)
        times[k] = (time.perf_counter() - t0) * 1e3
        x = gru.step(model.params, x, model.normalize_u(step.u))
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args(argv)
    mpc = RobustMPC(GRUModel.load(DEFAULT_MODEL), MPCOptions.from_mapping({}))
    closed_loop(mpc, 10, True)   # the kernel built, numpy warm
    runs = {"baseline": [], "changes": []}
    for _ in range(args.rounds):   # interleaved: the machine's load alike
        for name in runs:
            runs[name].append(closed_loop(mpc, args.steps, name == "changes"))
    p99 = {}
    for name, parts in runs.items():
        t = np.concatenate(parts)
        p99[name] = float(np.percentile(t, 99))
        print(f"{name:<9} median {np.median(t):.3f} p90 {np.percentile(t, 90):.3f} "
              f"p99 {p99[name]:.3f} max {t.max():.3f} ms over {t.size} steps")
    ratio = p99["changes"] / p99["baseline"]
    print(f"ratio p99 {ratio:.2f}x (target <= 2)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
