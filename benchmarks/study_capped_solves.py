"""Why some FHOCP solves need many SQP iterations: the study behind the p99 of the controller
step (docs/design/compiled-kernel.md, "Why the capped solves are slow to converge").

The paper scenario in closed loop with the plant FMU and the robust MPC's paper law
(``law="paper"``, the law this study was made on; the tracking law's iterations:
``bench_tracking.py``). Printed:

1. the solves that stop at the 15-iteration cap, and how many iterations the same run's
   solves need without the cap (``max_iter=200``);
2. casadi's per-call timers of ``sqpmethod`` (QP, Hessian, Jacobian, function values and
   line search), per iteration, over all solves and over the capped ones;
3. the active sets at the last iterate (multipliers ≠ 0): rows of the ∞-norm terminal
   epigraph, output-constraint rows, input bounds, in capped solves and in solves of at most
   3 iterations;
4. at the first capped solve: the Hessian of the Lagrangian against central differences of
   the Lagrangian's gradient, and its smallest eigenvalues;
5. with ``--sweep``: the capped solves and the QP time under other SQP settings (clipping
   margin, ``tol_du``, ``merit_memory``, ``c1``, ``init_feasible``), with ``H + ρ JₐᵀJₐ``
   (active constraints and input bounds) before the clipping on the numpy path, and with
   other QP solvers or qpOASES options;
6. with ``--paths``: whether the SQP's path chooses the answer (the FHOCP is nonconvex).
   Every FHOCP of the closed loop solved to convergence (``max_iter=200``) is solved again
   from the same initial guess and multipliers with another line search (:data:`PATH_LS`):
   the solves where both converge to first inputs more than :data:`PATH_TOL` apart
   (normalised), with their costs; then the whole closed loop under that line search
   against the default's: the largest difference of the answers' first inputs, as a share
   of their range, and the first step where it exceeds the regression references' 1e-4.

It reads solver internals (the FHOCP's casadi buffer and NLP object) on purpose: it is a
study, not an API user. Not part of ``make bench`` (it measures no speed target).

Usage: ``.venv/bin/python benchmarks/study_capped_solves.py [--sweep] [--paths]``
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.ocp import nlp_single_shooting  # noqa: E402
from controllers.ocp.solver_settings import SQP_OPTIONS  # noqa: E402
from cosim.adapters.robust_mpc import RobustMPCController  # noqa: E402

SCENARIO = ROOT / "scenarios" / "paper_steps.csv"
CAP = 15
TIMERS = ("QP", "nlp_hess_l", "nlp_jac_fg", "nlp_fg", "linesearch")


@contextlib.contextmanager
def sqp_settings(overrides: dict[str, Any]) -> Iterator[None]:
    """``SQP_OPTIONS`` with ``overrides`` while controllers are built (an FHOCP copies them)."""
    saved = dict(SQP_OPTIONS)
    SQP_OPTIONS.update(overrides)
    try:
        yield
    finally:
        SQP_OPTIONS.clear()
        SQP_OPTIONS.update(saved)


@contextlib.contextmanager
def active_set_convexification(rho: float) -> Iterator[None]:
    """The numpy path's QP Hessian becomes ``H + ρ JₐᵀJₐ`` (rows of the constraints with a
    nonzero multiplier, and inputs at a bound) before the eigenvalue clipping."""
    cls = nlp_single_shooting.SingleShootingNLP
    original = cls.hessian_convex

    def hessian_convex(self: Any, wv: np.ndarray, pv: np.ndarray, lf: np.ndarray,
                       lg: np.ndarray) -> list:
        H = self.hessian(wv, pv, lf, lg)
        _, J = self.jacobian(wv, pv)
        Ja = J[np.abs(lg) > 0]
        H = H + rho * Ja.T @ Ja
        at_bound = self.iu[np.abs(wv[self.iu]) >= 1 - 1e-9]
        H[at_bound, at_bound] += rho
        ev, V = np.linalg.eigh(H)
        if ev[0] < self.eigen_clip:
            H = (V * np.maximum(ev, self.eigen_clip)) @ V.T
        return [H]

    cls.hessian_convex = hessian_convex
    try:
        yield
    finally:
        cls.hessian_convex = original


def closed_loop(kernel: str = "auto", max_iter: int = CAP,
                sqp: dict[str, Any] | None = None) -> tuple[Any, list[dict[str, Any]]]:
    """One run of the paper scenario; per solve: the result, its iterations, its timers
    [s], the FHOCP's data and parameter vector, and the solver's last iterate."""
    from cosim.core import scenario
    from cosim.core.fmu import FmuComponent
    from cosim.core.master import Master

    with sqp_settings(sqp or {}):
        ctrl = RobustMPCController(law="paper", kernel=kernel, max_iter=max_iter)
    fh, solves, before = ctrl.mpc.fhocp, [], dict.fromkeys(TIMERS, 0.0)
    solve = fh.solve

    def recorded(x_hat: np.ndarray, e_o: float, x_bar: np.ndarray, u_bar: np.ndarray,
                 alpha: float, *args: Any, **kwargs: Any) -> Any:
        res = solve(x_hat, e_o, x_bar, u_bar, alpha, *args, **kwargs)
        buf, _, ins, outs = fh._buffer
        stats = buf.stats()
        timers = {k: stats.get(f"t_wall_{k}", 0.0) - before[k] for k in TIMERS}
        before.update({k: stats.get(f"t_wall_{k}", 0.0) for k in TIMERS})
        solves.append({"result": res, "iterations": res.iterations, "timers": timers,
                       "p": ins["p"].copy(), "w": outs["x"].copy(),
                       "ins": {k: v.copy() for k, v in ins.items()}})
        return res

    fh.solve = recorded
    result = Master(FmuComponent(ROOT / "fmus" / "FourTank.fmu"), ctrl,
                    scenario.load(SCENARIO)).run()
    if result.status != "ok":
        raise SystemExit(f"study_capped_solves: the run failed: {result.reason}")
    return ctrl, solves


def capped(solves: list[dict[str, Any]]) -> np.ndarray:
    return np.array([s["iterations"] >= CAP for s in solves])


def report_iterations(solves: list[dict[str, Any]], uncapped: list[dict[str, Any]]) -> None:
    it = np.array([s["iterations"] for s in solves])
    it_free = np.array([s["iterations"] for s in uncapped])
    print(f"1. {len(it)} solves: {capped(solves).sum()} stop at the {CAP}-iteration cap "
          f"(mean {it.mean():.2f} iterations); without the cap (max_iter=200) "
          f"{np.sum(it_free >= CAP)} solves need {CAP} or more, "
          f"{it_free[it_free >= CAP].min()}–{it_free.max()} iterations")


def report_timers(solves: list[dict[str, Any]]) -> None:
    mask = capped(solves)
    for label, group in (("all iterations", solves),
                         ("capped solves", [s for s, c in zip(solves, mask, strict=True) if c])):
        iters = sum(s["iterations"] for s in group)
        parts = ", ".join(f"{k} {1e3 * sum(s['timers'][k] for s in group) / iters:.3f}"
                          for k in TIMERS)
        print(f"2. per SQP iteration [ms], {label} ({iters}): {parts}")


def report_active_sets(ctrl: Any, solves: list[dict[str, Any]]) -> None:
    p = ctrl.mpc.fhocp._nlp.p
    n_out = (p.N - 1) * p.qr
    iu = ctrl.mpc.fhocp.iu.ravel()
    counts = np.array([[np.sum(np.abs(s["result"].lam_g[n_out:]) > 1e-10),
                        np.sum(np.abs(s["result"].lam_g[:n_out]) > 1e-10),
                        np.sum(np.abs(s["result"].lam_x[iu]) > 1e-10)] for s in solves])
    its = np.array([s["iterations"] for s in solves])
    for label, m in (("capped", its >= CAP), ("<= 3 iterations", its <= 3)):
        c = counts[m]
        print(f"3. {label:16s} ({m.sum():4d} solves): terminal epigraph rows active "
              f"{c[:, 0].mean():.1f} of {2 * p.n} (max {c[:, 0].max()}), output rows "
              f"{c[:, 1].mean():.2f}, an input bound active in {np.mean(c[:, 2] > 0):.0%}")


def report_hessian(ctrl: Any, solves: list[dict[str, Any]]) -> None:
    k = next(i for i, s in enumerate(solves) if s["iterations"] >= CAP)
    first = solves[k]
    nlp, w, p = ctrl.mpc.fhocp._nlp, first["w"], first["p"]
    lg = first["result"].lam_g
    H = nlp.hessian(w, p, np.array([1.0]), lg)

    def grad_lagrangian(wv: np.ndarray) -> np.ndarray:
        _, grad = nlp.gradient(wv, p)
        _, J = nlp.jacobian(wv, p)
        return grad + np.asarray(J).T @ lg

    eps = 1e-6
    H_fd = np.empty_like(H)
    for j in range(len(w)):
        d = np.zeros(len(w))
        d[j] = eps
        H_fd[:, j] = (grad_lagrangian(w + d) - grad_lagrangian(w - d)) / (2 * eps)
    ev = np.linalg.eigvalsh(H)
    print(f"4. Hessian at the first capped solve (step {k}, t = {25.0 * k:g} s): largest "
          f"|H - central differences| {np.max(np.abs(H - H_fd)):.1e} on entries up to "
          f"{np.max(np.abs(H)):.1e}; smallest eigenvalues {np.array2string(ev[:3], precision=3)}")


SWEEP: list[tuple[str, dict[str, Any], float | None]] = [
    ("default", {}, None),
    *[(f"hessian_eigen_clip={c:g}", {"hessian_eigen_clip": c}, None)
      for c in (1e-6, 1e-4, 1e-3, 3e-3, 3e-2)],
    ("tol_du=1e-5", {"tol_du": 1e-5}, None),
    ("merit_memory=1", {"merit_memory": 1}, None),
    ("merit_memory=10", {"merit_memory": 10}, None),
    ("c1=1e-8", {"c1": 1e-8}, None),
    ("init_feasible", {"init_feasible": True}, None),
    *[(f"numpy path, H + {r:g} JaᵀJa", {}, r) for r in (1.0, 10.0, 100.0)],
    ("qpOASES posdef, no regularisation",
     {"qpsol_options": {**SQP_OPTIONS["qpsol_options"], "hessian_type": "posdef",
                        "enableRegularisation": False}}, None),
    ("qpsol=proxqp (dense)", {"qpsol": "proxqp", "qpsol_options": {
        "error_on_fail": False, "proxqp": {"backend": "dense", "eps_abs": 1e-9}}}, None),
    ("qpsol=hpipm", {"qpsol": "hpipm", "qpsol_options": {"error_on_fail": False}}, None),
]


def sweep() -> None:
    for label, sqp, rho in SWEEP:
        try:
            with active_set_convexification(rho) if rho else contextlib.nullcontext():
                ctrl, solves = closed_loop(kernel="numpy" if rho else "auto", sqp=sqp)
        except (Exception, SystemExit) as exc:  # a QP plugin that rejects the problem
            print(f"5. {label:34s} fails: {str(exc).strip().splitlines()[-1][:100]}")
            continue
        it = np.array([s["iterations"] for s in solves])
        qp_ms = 1e3 * sum(s["timers"]["QP"] for s in solves) / it.sum()
        summary = ctrl.summary()
        print(f"5. {label:34s} capped {capped(solves).sum():3d}, mean iterations "
              f"{it.mean():.2f}, QP {qp_ms:.3f} ms/iteration, fallbacks "
              f"{summary['fallbacks']}, suboptimal {summary['suboptimal_steps']}")


#: Item 6's other line search (the kernel SQP's options) and the difference of two first
#: inputs (normalised) that counts as another answer.
PATH_LS = {"max_iter_ls": 10, "beta": 0.5}
PATH_TOL = 1e-3


def first_inputs(ctrl: Any, solves: list[dict[str, Any]]) -> np.ndarray:
    """Each solve's answer's first input (normalised, ``solves × m``)."""
    m = ctrl.mpc.fhocp.m
    return np.array([np.asarray(s["result"].u, dtype=float).reshape(-1, m)[0] for s in solves])


def report_paths(ctrl: Any, uncapped: list[dict[str, Any]]) -> None:
    """Item 6 (module docstring): ``uncapped`` is the default closed loop at
    ``max_iter=200``, ``ctrl`` its controller (its kernel SQP replays the solves)."""
    from controllers.kernel.kernel_sqp import STATUS

    sqp = ctrl.mpc.fhocp._buffer[0]
    if not hasattr(sqp, "options"):
        print("6. needs the compiled kernel's SQP (loop=\"kernel\")")
        return
    default = {k: getattr(sqp.options, k) for k in PATH_LS}
    apart = []
    for k, s in enumerate(uncapped):
        answers = []
        for opts in (default, PATH_LS):
            for key, value in opts.items():
                setattr(sqp.options, key, value)
            for key, value in s["ins"].items():
                sqp.ins[key][:] = value
            sqp.solve()
            answers.append((STATUS[sqp.info.status], float(sqp.outs["f"][0]),
                            sqp.outs["x"][: ctrl.mpc.fhocp.m].copy()))
        (st0, f0, u0), (st1, f1, u1) = answers
        if st0 == st1 == "Solve_Succeeded" and np.max(np.abs(u0 - u1)) > PATH_TOL:
            apart.append(f"step {k}: cost {f0:.4f} / {f1:.4f}, first input "
                         f"{np.max(np.abs(u0 - u1)):.3f} apart")
    for key, value in default.items():
        setattr(sqp.options, key, value)
    label = ", ".join(f"{k}={v:g}" for k, v in PATH_LS.items())
    print(f"6. the same {len(uncapped)} FHOCPs from the same guesses, to convergence with "
          f"the default line search and with {label}: {len(apart)} converge to first inputs "
          f"more than {PATH_TOL:g} apart (normalised){': ' if apart else ''}"
          + "; ".join(apart[:4]))
    _, other = closed_loop(max_iter=200, sqp=PATH_LS)
    a, b = first_inputs(ctrl, uncapped), first_inputs(ctrl, other)
    span = np.maximum(a.max(axis=0) - a.min(axis=0), 1e-12)
    share = np.max(np.abs(a - b) / span, axis=1)
    beyond = np.flatnonzero(share > 1e-4)
    print(f"6. the closed loop with {label} (max_iter=200): its answers' first inputs differ "
          f"from the default's by up to {share.max():.2f} of their range"
          + (f", first beyond 1e-4 at step {beyond[0]} ({beyond.size} steps in all)"
             if beyond.size else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sweep", action="store_true", help="also run the SQP-setting sweep")
    ap.add_argument("--paths", action="store_true",
                    help="also replay the solves with another line search (item 6)")
    args = ap.parse_args()
    if not (ROOT / "fmus" / "FourTank.fmu").exists():
        raise SystemExit("study_capped_solves: build the plant FMU first (make fmus)")
    ctrl, solves = closed_loop()
    ctrl_free, uncapped = closed_loop(max_iter=200)
    report_iterations(solves, uncapped)
    report_timers(solves)
    report_active_sets(ctrl, solves)
    report_hessian(ctrl, solves)
    if args.sweep:
        sweep()
    if args.paths:
        report_paths(ctrl_free, uncapped)


if __name__ == "__main__":
    main()
