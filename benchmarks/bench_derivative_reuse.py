"""The kernel SQP's derivative reuse (``reuse_step``) on the tracking law's solves.

The paper scenario's first ``--seconds`` (default all of it) in closed loop with the
four-tank FMU and ``law="tracking"`` (default options); every FHOCP solve's inputs are
captured, then replayed through the same compiled SQP with ``reuse_step`` = 0 (the baseline:
``sqpmethod``'s iteration, fresh derivatives at every iteration) and with each value of
``--reuse``, the variants interleaved, each solve timed best of ``--repeats``. Printed per
variant: the solve's median and p99 [ms] and their ratios to the baseline, the iterations
(all, and those with new derivatives), failures, and the largest difference of the answers
from the baseline's (docs: design/tracking.md, "The step time"; design/compiled-kernel.md,
"The SQP inside the kernel").

It reads the FHOCP's kernel SQP (its argument buffers) on purpose: a study of one solver
option, not an API user.

Usage: ``.venv/bin/python benchmarks/bench_derivative_reuse.py [--seconds S] [--repeats R]
[--reuse 0.01 0.1]``
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

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

from bench_tracking import scenario_file  # noqa: E402

import cosim  # noqa: E402
from controllers.kernel import kernel_sqp  # noqa: E402
from cosim.core import registry  # noqa: E402

OPTIONS = {"law": "tracking"}


def capture(seconds: float | None) -> list[dict[str, np.ndarray]]:
    """The inputs of every kernel SQP solve of the closed loop."""
    caps: list[dict[str, np.ndarray]] = []
    solve = kernel_sqp.KernelSQP.solve

    def recording(self: kernel_sqp.KernelSQP) -> None:
        caps.append({k: v.copy() for k, v in self.ins.items()})
        solve(self)

    kernel_sqp.KernelSQP.solve = recording
    try:
        with tempfile.TemporaryDirectory() as tmp:
            run = cosim.run(scenario_file(seconds, Path(tmp)), controller="robust-mpc",
                            options=OPTIONS)
    finally:
        kernel_sqp.KernelSQP.solve = solve
    if run.status != "ok":
        raise SystemExit(f"bench_derivative_reuse: the run {run.status}: {run.reason}")
    return caps


def solver(reuse: float) -> kernel_sqp.KernelSQP:
    """The tracking law's kernel SQP with ``reuse_step = reuse``."""
    fh = registry.create("robust-mpc", OPTIONS).mpc.fhocp.setup()
    sqp = fh._buffer[0]
    if not isinstance(sqp, kernel_sqp.KernelSQP):
        raise SystemExit("bench_derivative_reuse: no compiled kernel (cosim build-kernel)")
    sqp.options.reuse_step = reuse
    return sqp


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--reuse", type=float, nargs="+", default=[0.01, 0.1])
    args = parser.parse_args()
    caps = capture(args.seconds)
    variants = {r: solver(r) for r in [0.0, *args.reuse]}
    best = {r: np.full(len(caps), np.inf) for r in variants}
    answers = {r: [] for r in variants}
    counts = {r: [0, 0, 0] for r in variants}     # iterations, reuses, failures
    for rep in range(args.repeats):
        for j, ins in enumerate(caps):
            for r, sqp in variants.items():   # interleaved: the same minute for every variant
                for k, v in ins.items():
                    sqp.ins[k][:] = v
                t0 = time.perf_counter()
                sqp.solve()
                best[r][j] = min(best[r][j], time.perf_counter() - t0)
                if rep == 0:
                    st = sqp.stats()
                    answers[r].append(sqp.outs["x"].copy())
                    counts[r][0] += st["iter_count"]
                    counts[r][1] += st["derivative_reuses"]
                    counts[r][2] += not st["success"]
    base = np.median(best[0.0]), np.percentile(best[0.0], 99)
    print(f"{len(caps)} tracking-law solves of the paper scenario, best of {args.repeats}")
    print(f"{'reuse_step':>10} {'median [ms]':>12} {'p99 [ms]':>9} {'ratio':>11} "
          f"{'iterations':>10} {'new derivatives':>15} {'failures':>8} {'max |w - w0|':>12}")
    for r in variants:
        med, p99 = np.median(best[r]), np.percentile(best[r], 99)
        diff = float(np.max(np.abs(np.array(answers[r]) - np.array(answers[0.0]))))
        it, reused, failed = counts[r]
        print(f"{r:>10g} {med * 1e3:>12.3f} {p99 * 1e3:>9.3f} "
              f"{med / base[0]:>5.2f}/{p99 / base[1]:<5.2f} {it:>10d} {it - reused:>15d} "
              f"{failed:>8d} {diff:>12.2e}")


if __name__ == "__main__":
    main()
