"""The paper's FHOCP in acados beside this project's compiled kernel, on the same problems
(issue 48, goal 4; aim: no slower than acados' SQP at the median and the p99, answers as good
or better).

The robust MPC with the paper's law runs the paper scenario (``scenarios/paper_steps.csv``)
in closed loop with the four-tank FMU, its constraints hard (``hard_constraints``: the
paper's FHOCP, without the slacks of ``controllers.ocp.soft``); every FHOCP its SQP solves
is captured (``x̂``, the set-point's ``x̄, ū``, the tightened output rows' bounds, the
terminal radius α, the initial guess). Then, in this run:

* **kernel**: each captured problem solved again by the compiled kernel's SQP
  (:class:`controllers.kernel.kernel_sqp.KernelSQP`, the controller's options: exact
  eigenvalue-clipped Hessian, 15 iterations at most) from the captured guess and duals;
* **acados** (``acados_fhocp.py`` in the acados venv, ``make acados``): the same FHOCP as an
  acados OCP (multiple shooting, the condensed QP by qpOASES), from the same primal guess, as
  SQP with the exact Hessian (eigenvalues projected, acados' counterpart of the clipping)
  under the kernel's iteration cap and with 100 iterations, SQP with the Gauss-Newton
  Hessian, and SQP-RTI (one Gauss-Newton iteration per solve); the kernel's tolerances.

Each solve's time is the best of ``--repeats`` (wall clock around the solve call and, for
acados, the per-solve ``set`` calls it needs). Every answer is then judged the same way,
without either solver: its inputs rolled out by numpy (``controllers.gru``), its cost
``eq:optimization-cost`` (with ``t = ‖x_N − x̄‖∞``), the output rows', input box's and
terminal set's violations. Printed per solver: the solve's median / p99 / max [ms],
iterations, failures (statuses other than success), the cost against the kernel's (median
relative difference, solves better / worse by more than 1e-6) and the solves violating a
constraint by more than 1e-6.

Usage::

    make acados       # once: .venv-acados with the comma-deps-acados wheel
    .venv/bin/python benchmarks/bench_acados.py [--repeats 3] [--acados-python PATH]
        [--keep DIR] [--problems K] [--variants sqp-exact,sqp-rti]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: Violations and cost differences below this are rounding.
TOL = 1e-6
#: The arrays of :func:`problems` with one row per captured problem.
PER_PROBLEM = ("x_hat", "x_bar", "u_bar", "u_init", "t_init", "alpha", "rows")


def capture() -> tuple[dict[str, np.ndarray], list[dict], object]:
    """The paper scenario in closed loop, every FHOCP the kernel's SQP solved: the problem
    arrays for ``acados_fhocp.py``, the SQP's argument buffers per solve, and the FHOCP."""
    import controllers.kernel.kernel_sqp as ks
    from cosim import api
    from cosim.adapters.robust_mpc import RobustMPCController

    solved: list[dict] = []
    original = ks.KernelSQP.solve

    def keep(self: ks.KernelSQP) -> None:
        ins = {k: v.copy() for k, v in self.ins.items()}
        original(self)
        solved.append(ins)

    ks.KernelSQP.solve = keep
    fhocps = []
    make = RobustMPCController.setup

    def remember(self: RobustMPCController, t0: float) -> None:
        make(self, t0)
        fhocps.append(self.mpc.fhocp)

    RobustMPCController.setup = remember
    try:
        run = api.run(ROOT / "scenarios" / "paper_steps.csv",
                      options={"law": "paper", "hard_constraints": True}, figure=False)
    finally:
        ks.KernelSQP.solve, RobustMPCController.setup = original, make
    if run.status != "ok":
        raise SystemExit(f"bench_acados: the closed loop {run.status}: {run.reason}")
    fh = fhocps[-1]
    return problems(fh, solved), solved, fh


def problems(fh: object, solved: list[dict]) -> dict[str, np.ndarray]:
    """The captured solves as ``acados_fhocp.py`` reads them."""
    from controllers.kernel.compiled_kernel import KernelProblem

    kp = KernelProblem.of(fh)
    n, m, N = fh.n, fh.m, fh.N
    q = kp.DUo.shape[0]
    r = (N - 1) * q
    for ins in solved:   # the terminal rows: x_N − x̄ − t ≤ 0 ≤ x_N − x̄ + t
        assert np.all(ins["ubg"][r:r + n] == 0) and np.all(ins["lbg"][r + n:] == 0)
    p = np.array([ins["p"] for ins in solved])
    return {
        **{f"P_{k}": np.asarray(v, dtype=float) for k, v in fh.params.items()},
        "N": np.array(N), "Q": np.asarray(fh.Q), "R": np.asarray(fh.R), "s": np.array(fh.s),
        "DUo": np.asarray(kp.DUo),
        "x_hat": p[:, :n], "x_bar": p[:, n:2 * n], "u_bar": p[:, 2 * n:2 * n + m],
        "u_init": np.array([ins["x0"][:N * m].reshape(N, m) for ins in solved]),
        "t_init": np.array([ins["x0"][-1] for ins in solved]),
        "alpha": np.array([ins["ubx"][-1] for ins in solved]),
        "rows": np.array([np.stack([ins["lbg"][:r].reshape(N - 1, q),
                                    ins["ubg"][:r].reshape(N - 1, q)], axis=1)
                          for ins in solved]),
    }


def kernel_solves(fh: object, solved: list[dict], repeats: int) -> dict[str, np.ndarray]:
    """Each captured problem solved again by the kernel's SQP (best time of ``repeats``)."""
    from controllers.kernel.kernel_sqp import KernelSQP

    opts = {k: v for k, v in fh.sqp_options.items() if k not in ("loop", "hessian_eigen_clip")}
    sqp = KernelSQP(fh.kernel, opts)
    K, N, m = len(solved), fh.N, fh.m
    out = {"u": np.zeros((K, N, m)), "ms": np.full(K, np.inf), "iterations": np.zeros(K, int),
           "status": np.zeros(K, int)}
    for _ in range(repeats):
        for k, ins in enumerate(solved):
            for key, v in ins.items():
                sqp.ins[key][:] = v
            t0 = time.perf_counter()
            sqp.solve()
            out["ms"][k] = min(out["ms"][k], (time.perf_counter() - t0) * 1e3)
            st = sqp.stats()
            out["u"][k] = sqp.outs["x"][:N * m].reshape(N, m)
            out["iterations"][k] = st["iter_count"]
            out["status"][k] = 0 if st["success"] else 1
    return out


def judge(data: dict[str, np.ndarray], U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cost and largest violation of each answer ``U`` (K, N, m), by numpy alone."""
    from controllers import gru

    P = {k[2:]: v for k, v in data.items() if k.startswith("P_")}
    Q, R, s, D = data["Q"], data["R"], float(data["s"]), data["DUo"]
    cost, viol = np.zeros(len(U)), np.zeros(len(U))
    for k, u in enumerate(U):
        x = gru.simulate(P, data["x_hat"][k], u)[0]
        dx, du = x[:-1] - data["x_bar"][k], u - data["u_bar"][k]
        t = float(np.max(np.abs(x[-1] - data["x_bar"][k])))
        cost[k] = np.vdot(dx @ Q, dx) + np.vdot(du @ R, du) + s * t * t
        y = x[1:-1] @ D.T
        lo, hi = data["rows"][k][:, 0], data["rows"][k][:, 1]
        viol[k] = max(0.0, float(np.max(lo - y)), float(np.max(y - hi)),
                      float(np.max(np.abs(u))) - 1.0, t - float(data["alpha"][k]))
    return cost, viol


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--acados-python", type=Path,
                        default=ROOT / ".venv-acados" / "bin" / "python")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the captured problems and acados' answers in this folder")
    parser.add_argument("--problems", type=int, default=None,
                        help="only the first K captured problems")
    parser.add_argument("--variants", default=None,
                        help="acados variants (acados_fhocp.VARIANTS; default all)")
    args = parser.parse_args(argv)
    if not args.acados_python.is_file():
        raise SystemExit(f"bench_acados: {args.acados_python} missing: run make acados")
    data, solved, fh = capture()
    if args.problems is not None:
        solved = solved[:args.problems]
        data = {k: v[:args.problems] if k in PER_PROBLEM else v for k, v in data.items()}
    K = len(solved)
    with tempfile.TemporaryDirectory(prefix="bench-acados-") as tmp_dir:
        tmp = args.keep or Path(tmp_dir)
        tmp.mkdir(parents=True, exist_ok=True)
        np.savez(Path(tmp) / "problems.npz", **data)
        ours = kernel_solves(fh, solved, args.repeats)
        proc = subprocess.run([str(args.acados_python), str(ROOT / "benchmarks" /
                                                            "acados_fhocp.py"),
                               str(Path(tmp) / "problems.npz"), "--out",
                               str(Path(tmp) / "acados.npz"), "--repeats",
                               str(args.repeats), "--max-iter",
                               str(fh.sqp_options["max_iter"]),
                               *(["--variants", args.variants] if args.variants else [])],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"bench_acados: acados failed:\n{proc.stderr[-3000:]}")
        theirs = dict(np.load(Path(tmp) / "acados.npz"))
    variants = sorted({k.split(".")[0] for k in theirs})
    results = {"kernel": ours, **{v: {k.split(".", 1)[1]: a for k, a in theirs.items()
                                      if k.startswith(v + ".")} for v in variants}}
    base_cost, _ = judge(data, ours["u"])
    print(f"paper's FHOCP (N = {fh.N}, n = {fh.n}, m = {fh.m}) on the {K} problems of the "
          f"paper scenario's closed loop; best of {args.repeats}")
    print(f"{'solver':13s} {'median':>7s} {'p99':>7s} {'max':>7s} ms  iter med/max  failed  "
          "cost vs kernel: median rel.  better  worse  violating")
    for name, res in results.items():
        ms = np.asarray(res["ms"])
        cost, viol = judge(data, res["u"])
        rel = (cost - base_cost) / (1.0 + np.abs(base_cost))
        it = np.asarray(res["iterations"])
        print(f"{name:13s} {np.median(ms):7.3f} {np.percentile(ms, 99):7.3f} {ms.max():7.3f}"
              f"     {np.median(it):4.0f} /{it.max():3d}  {int(np.sum(res['status'] != 0)):6d}"
              f"  {np.median(rel):+26.1e}  {int(np.sum(rel < -TOL)):6d} "
              f"{int(np.sum(rel > TOL)):6d} {int(np.sum(viol > TOL)):10d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
