"""The controller step's tail on the paper scenario, this tree against an earlier one in the same
run (issue 48, goal 3: median no slower than the previous release, p99 at most 2 ms).

For each law (the paper's, the default tracking law) the robust MPC runs the paper scenario
(``scenarios/paper_steps.csv``, 1,601 steps) in closed loop with the four-tank FMU, in a fresh
process per run, once per round for this tree and for ``--baseline`` (a git revision, unpacked
with ``git archive`` into a temporary folder; its kernels are compiled into the same cache,
keyed by their source), alternating which goes first so that the machine's load hits both
alike. Timed: the whole controller step (``RobustMPCController.step``: observer, governor,
FHOCP and its answer check), as ``cosim run`` calls it.

Printed per law and tree: median, p90, p99 and max of the step [ms] over all rounds, the
ratios this / baseline, and what the slowest 1 % of this tree's steps are: their SQP
iterations, how many hit the iteration cap, how many fall within two samples of a set-point
change and (the paper's law) how many while its reference governor holds the reference short
of the set-point, and where their time goes (the SQP, the paper law's set-point handling
with its governor, the rest); then whether both trees applied the same inputs (largest
difference as a share of the input box).

``--split`` prints instead, for this tree and the baseline, where the kernel spends a slow
solve's iterations: the solves of one closed loop of the paper's law that take 12 SQP
iterations or more, each replayed 20 times from its captured initial guess (the fastest
kept), per iteration by the SQP's timers: the QP, the Hessian and its eigenvalue clipping
(a tree without the clipping's own timer counts it in the Hessian), f/g and their
derivatives, the line search; with the clipping's decompositions where the tree counts them.

Usage::

    .venv/bin/python benchmarks/bench_step_tail.py [--baseline REV] [--rounds 3]
        [--laws paper,tracking] [--split]

The baseline must have ``cosim.api.run`` and ``cosim.adapters.robust_mpc`` or, before issue
59, ``cosim_adapters.robust_mpc`` (every tree since the controller moved into its adapter
package).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "scenarios/paper_steps.csv"

#: Run in the tree's folder (its packages first on sys.path): one closed loop, the step timed.
CHILD = r"""
import json, sys, time
import numpy as np
from cosim import api
try:   # the adapters' package: cosim.adapters (issue 59), before it cosim_adapters
    from cosim.adapters.robust_mpc import RobustMPCController
except ImportError:
    from cosim_adapters.robust_mpc import RobustMPCController

law, plant, out = sys.argv[1], sys.argv[2], sys.argv[3]
times, acc, parts = [], {"sqp": 0.0, "setpoint": 0.0}, {"sqp": [], "setpoint": []}
original = RobustMPCController.step

def timing(module, cls, name, key):
    # acc[key] += the seconds in cls.name, where the tree has it
    try:
        owner = getattr(__import__(module, fromlist=[cls]), cls)
    except (ImportError, AttributeError):
        return
    f = getattr(owner, name, None)
    if f is None:
        return
    def g(*a, **k):
        t0 = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            acc[key] += time.perf_counter() - t0
    setattr(owner, name, g)

timing("controllers.kernel.kernel_sqp", "KernelSQP", "solve", "sqp")
timing("controllers.laws.paper.law", "PaperLaw", "_update_reference", "setpoint")
timing("cosim_adapters.paper_law", "PaperLaw", "_update_reference", "setpoint")   # before 59

def timed(self, t, dt):
    acc["sqp"] = acc["setpoint"] = 0.0
    t0 = time.perf_counter()
    original(self, t, dt)
    times.append((time.perf_counter() - t0) * 1e3)
    for key in parts:
        parts[key].append(acc[key] * 1e3)

RobustMPCController.step = timed
run = api.run("scenarios/paper_steps.csv", plant=plant, options={"law": law}, figure=False)
cols = list(run.result.columns)
rows = np.asarray(run.result.rows, dtype=float)
pick = lambda name: rows[:, cols.index(name)].tolist() if name in cols else []
json.dump({"status": run.status, "ms": times, "sqp_ms": parts["sqp"],
           "setpoint_ms": parts["setpoint"], "time": pick("time"),
           "iterations": pick("ctrl.iterations"), "governor": pick("ctrl.governor_lambda"),
           "inputs": {u: pick(f"ctrl.{u}") for u in run.result.inputs},
           "refs": {r: pick(f"ref.{r}") for r in run.result.references},
           # an older tree's summary may not carry its options: the largest count seen
           "max_iter": run.summary["controller_summary"].get("options", {}).get(
               "max_iter") or int(max(pick("ctrl.iterations")))},
          open(out, "w"))
"""

#: Run in this tree: the paper law's solves of >= 12 iterations captured, then replayed.
CHILD_SPLIT = r"""
import sys, time
import numpy as np
from cosim import api
from controllers.kernel import kernel_sqp

plant, replays = sys.argv[1], int(sys.argv[2])
solves, last = [], []
original = kernel_sqp.KernelSQP.solve

def capture(self):
    ins = {k: v.copy() for k, v in self.ins.items()}
    original(self)
    last[:] = [self]
    if self.info.iterations >= 12:
        solves.append(ins)

kernel_sqp.KernelSQP.solve = capture
api.run("scenarios/paper_steps.csv", plant=plant, options={"law": "paper"}, figure=False)
kernel_sqp.KernelSQP.solve = original
sqp = last[0]
names = ("qp", "hessian", "clip", "derivatives", "line_search")
ws = getattr(sqp, "workspace", None)   # an older tree's solver does not keep it
counters = ws.counters if ws is not None else dict
total, iterations, before = np.zeros(6), 0, counters()
for ins in solves:
    best = None
    for _ in range(replays):
        for k, v in ins.items():
            sqp.ins[k][:] = v
        t0 = time.perf_counter()
        sqp.solve()
        wall = time.perf_counter() - t0
        if best is None or wall < best[0]:
            i = sqp.info
            clip = getattr(i, "t_clip", 0.0)
            best = (wall, i.t_qp, i.t_hessian - clip, clip, i.t_derivatives, i.t_line_search,
                    i.iterations)
    total += best[1:6] + (best[0],)
    iterations += best[6]
after = counters()
us = 1e6 * total / max(iterations, 1)
print(f"  {len(solves)} solves of >= 12 iterations, {iterations} iterations, best of {replays}")
if not hasattr(sqp.info, "t_clip"):
    names = ("qp", "hessian (clip included)", "clip", "derivatives", "line_search")
print("  per iteration [us]: " + ", ".join(f"{n} {v:.1f}" for n, v in zip(names, us[:5])
                                         if n != "clip" or hasattr(sqp.info, "t_clip"))
      + f"; the whole solve {us[5]:.1f}")
if after:
    runs = max(replays * len(solves), 1)
    print(f"  clipping per solve: {(after['eig'] - before['eig']) / runs:.1f} decompositions, "
          f"{(after['eigenvalues_clipped'] - before['eigenvalues_clipped']) / runs:.1f} "
          f"eigenvalues clipped, "
          f"{(after.get('full_eig', 0) - before.get('full_eig', 0)) / runs:.2f} "
          "full decompositions")
"""


def unpack(rev: str, folder: Path) -> Path:
    """The tree of ``rev`` (``git archive``) in ``folder``."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev],
                          check=True, capture_output=True).stdout
    tar = folder / "tree.tar"
    tar.write_bytes(data)
    tree = folder / "tree"
    with tarfile.open(tar) as t:
        t.extractall(tree, filter="data")
    return tree


def one_run(tree: Path, law: str, plant: Path, out: Path) -> dict:
    """One closed loop of ``law`` with ``tree``'s packages, in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", CHILD, law, str(plant), str(out)], cwd=tree,
                          env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"bench_step_tail: {tree} law={law} failed:\n{proc.stderr[-2000:]}")
    found = json.loads(out.read_text())
    if found["status"] != "ok":
        raise SystemExit(f"bench_step_tail: {tree} law={law}: run {found['status']}")
    return found


def split(trees: dict[str, Path], plant: Path) -> int:
    """Print where each tree's kernel spends a slow solve's iterations (``--split``)."""
    for name, tree in trees.items():
        env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
        proc = subprocess.run([sys.executable, "-c", CHILD_SPLIT, str(plant), "20"], cwd=tree,
                              env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"bench_step_tail --split: {tree} failed:\n{proc.stderr[-2000:]}")
        print(f"{name}: the paper law's slow solves replayed")
        print(proc.stdout, end="")
    return 0


def stats(ms: np.ndarray) -> str:
    return (f"median {np.median(ms):6.3f}  p90 {np.percentile(ms, 90):6.3f}  "
            f"p99 {np.percentile(ms, 99):6.3f}  max {ms.max():6.3f} ms")


def tail(run: dict) -> str:
    """What the slowest 1 % of one run's steps are."""
    ms, it = np.asarray(run["ms"]), np.asarray(run["iterations"])
    t = np.asarray(run["time"])
    k = max(1, len(ms) // 100)
    slow = np.argsort(ms)[-k:]
    ref = np.column_stack([np.asarray(v) for v in run["refs"].values()])
    changed = np.flatnonzero(np.any(np.abs(np.diff(ref, axis=0)) > 0, axis=1)) + 1
    dt = t[1] - t[0]
    near = sum(bool(np.any((t[i] - t[changed] >= 0) & (t[i] - t[changed] <= 2 * dt)))
               for i in slow)
    held = (f", {int(np.sum(np.asarray(run['governor'])[slow] < 1))} with the governor's "
            "reference short of the set-point (lambda < 1)") if run["governor"] else ""
    sqp, setpoint = (np.asarray(run.get(k) or np.zeros(len(ms))) for k in
                     ("sqp_ms", "setpoint_ms"))
    spent = (f"; their mean {np.mean(ms[slow]):.2f} ms: SQP {np.mean(sqp[slow]):.2f}, "
             + (f"set-point handling (the governor) {np.mean(setpoint[slow]):.2f}, "
                if np.any(setpoint) else "")
             + f"the rest {np.mean(ms[slow] - sqp[slow] - setpoint[slow]):.2f}")
    return (f"slowest {k}: iterations median {np.median(it[slow]):.0f} (all steps "
            f"{np.median(it):.0f}), {int(np.sum(it[slow] >= run['max_iter']))} at the cap of "
            f"{run['max_iter']}, {near} within two samples of a set-point change{held}{spent}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default="HEAD", help="git revision (default HEAD)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--laws", default="paper,tracking")
    parser.add_argument("--split", action="store_true",
                        help="where this tree's kernel spends a slow solve's iterations")
    args = parser.parse_args(argv)
    plant = ROOT / "fmus" / "FourTank.fmu"
    if not plant.is_file():
        raise SystemExit(f"bench_step_tail: {plant} missing: run make fmus")
    laws = args.laws.split(",")
    with tempfile.TemporaryDirectory(prefix="bench-step-tail-") as tmp:
        base = unpack(args.baseline, Path(tmp))
        trees = {"this": ROOT, "baseline": base}
        if args.split:
            return split(trees, plant)
        runs: dict[tuple[str, str], list[dict]] = {}
        for r in range(args.rounds):
            for law in laws:
                order = ("this", "baseline") if r % 2 == 0 else ("baseline", "this")
                for name in order:
                    out = Path(tmp) / f"{name}-{law}-{r}.json"
                    runs.setdefault((name, law), []).append(
                        one_run(trees[name], law, plant, out))
                    print(f"round {r + 1}/{args.rounds} {law:8s} {name:8s} done", flush=True)
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.baseline],
                         capture_output=True, text=True).stdout.strip()
    print(f"\ncontroller step on {SCENARIO}, {args.rounds} rounds; baseline {args.baseline} "
          f"({rev}); {os.cpu_count()} CPUs")
    for law in laws:
        ms = {n: np.concatenate([run["ms"] for run in runs[(n, law)]]) for n in trees}
        print(f"{law} law")
        for n in trees:
            print(f"  {n:8s} {stats(ms[n])}")
        a, b = ms["this"], ms["baseline"]
        print(f"  ratio    median {np.median(a) / np.median(b):.2f}x  p99 "
              f"{np.percentile(a, 99) / np.percentile(b, 99):.2f}x  (aim: median <= 1, "
              f"p99 <= 2 ms)")
        print(f"  this tree's {tail(runs[('this', law)][0])}")
        first = runs[("this", law)][0]["inputs"], runs[("baseline", law)][0]["inputs"]
        gap = max((np.max(np.abs(np.subtract(first[0][c], first[1][c])))
                   / max(np.ptp(first[1][c]), 1e-300) for c in first[0]), default=0.0)
        print(f"  inputs: largest difference between the trees {gap:.1e} of their range")
    return 0


if __name__ == "__main__":
    sys.exit(main())
