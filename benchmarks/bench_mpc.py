"""Speed of the robust MPC controller step: the compiled kernel against the numpy baseline.

The paper's law (``law="paper"``: the problem the kernel and the do-mpc comparison of issue 5
were measured on; the default tracking law's step: ``bench_tracking.py``). The controller step
(observer + reference governor + FHOCP: what ``ctrl.step`` does, as in ``timings.csv``) on
the paper scenario (``scenarios/paper_steps.csv``, 1,600 steps) in closed loop with the plant
FMU (the GRU model itself when no FMU is built), two ways in the same process, alternating
run by run so that the machine's load hits both alike:

* ``compiled``: the controller with its default kernel: the whole SQP (derivatives,
  eigenvalue clipping, QP, line search) and the governor's equilibria in the compiled kernel
  (:mod:`controllers.kernel.compiled_kernel`, :mod:`controllers.kernel.kernel_sqp`);
* ``numpy``: the same controller with ``kernel="numpy"``, the implementation before the
  kernel (numpy callbacks in casadi ``sqpmethod`` with qpOASES), kept as the baseline.

Printed: median and p99 of the step (wall clock and thread CPU time) for each, their ratios
(targets: ≥ 4× at the median, ≥ 5× at the p99), and the answers: the compiled controller's
optima against a tight IPOPT solve of the same FHOCP at every step (``--reference``; where
the two differ, IPOPT restarted from the compiled answer tells whether that answer is a
local optimum of the nonconvex FHOCP) and the two closed loops against each other.

``--scaling`` times random δISS GRUs (GRU plant, 5 set-points × 60 steps) for N = 15, 30, 60
(n = 20; ``--horizons``) and n = 20, 40, 80 (N = 15; ``--states``), compiled and numpy
(``--rounds`` each, alternating), splits both median steps into the SQP's QP, Hessian,
Jacobian, f, g and the rest, fits the growth exponents of the step and of its QP, and prints
the step time one more stage (state) adds, from the smallest size to the largest.
``--plain`` adds the do-mpc-style baseline of issue 5 (multiple shooting, IPOPT defaults).
``--clip`` times the Hessian's eigenvalue clipping, own eigenpairs against LAPACK dsyevr.

Usage::

    .venv/bin/python benchmarks/bench_mpc.py [--rounds 2] [--steps N] [--reference]
        [--scaling] [--plain] [--clip] [--plant fmu|model]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.laws.paper.reference import FixedSetpoint  # noqa: E402
from controllers.ocp.fhocp import FHOCP  # noqa: E402
from cosim.adapters.robust_mpc import RobustMPCController  # noqa: E402
from cosim.core.component import Component  # noqa: E402

#: The robust MPC's law this benchmark times (see the module docstring).
LAW = "paper"
#: The plain baseline may take seconds to declare infeasibility; cap it so the run ends.
PLAIN_OPTIONS = {"max_wall_time": 2.0}


class TimedController(Component):
    """Wraps a controller: wall and thread-CPU time of each ``step``; optionally solves the
    same FHOCP with a reference formulation alongside."""

    def __init__(self, ctrl: RobustMPCController, others: dict[str, FHOCP] | None = None
                 ) -> None:
        self.ctrl = ctrl
        self.others = others or {}
        self.name, self.inputs, self.outputs = ctrl.name, ctrl.inputs, ctrl.outputs
        self.direct_feedthrough = True
        self.sample_time, self.bounds = ctrl.sample_time, ctrl.bounds
        self.wall_ms: list[float] = []
        self.cpu_ms: list[float] = []
        self.u: list[np.ndarray] = []
        self.solves: dict[str, list[tuple[float, bool, float]]] = {k: [] for k in self.others}
        #: the FHOCP data of each step (x̂, ê_o, x̄, ū, α) when solving alongside
        self.problems: list[tuple] = []
        #: the controller's initial guess of each step's solve (its inputs, N×m)
        self.starts: list[np.ndarray] = []

    def setup(self, t0: float) -> None:
        self.ctrl.setup(t0)

    def set_inputs(self, values: dict[str, float]) -> None:
        self.ctrl.set_inputs(values)

    def get_outputs(self) -> dict[str, float]:
        return self.ctrl.get_outputs()

    def diagnostics(self) -> dict[str, float]:
        return self.ctrl.diagnostics()

    def step(self, t: float, dt: float) -> None:
        c0, w0 = time.thread_time(), time.perf_counter()
        self.ctrl.step(t, dt)
        self.wall_ms.append((time.perf_counter() - w0) * 1e3)
        self.cpu_ms.append((time.thread_time() - c0) * 1e3)
        mpc = self.ctrl.mpc.law.mpc
        rec = mpc.records[-1]
        self.u.append(rec.u.copy())
        if self.others:
            self.problems.append((rec.x_hat.copy(), rec.e_o, np.array(mpc.x_bar, copy=True),
                                  np.array(mpc.u_bar, copy=True), mpc.alpha))
            fh = self.ctrl.mpc.fhocp   # the solver's argument buffer still holds its start
            self.starts.append(fh._buffer[2]["x0"][fh.iu].reshape(fh.N, fh.m).copy())
        for name, fh in self.others.items():
            r = fh.solve(*self.problems[-1])
            self.solves[name].append((r.solve_time * 1e3, r.success, r.cost))


def closed_loop(ctrl: RobustMPCController, scenario: Path, plant_kind: str, steps: int | None,
                others: dict[str, FHOCP] | None = None) -> TimedController:
    """One closed-loop run; returns the timed wrapper."""
    from cosim.core import scenario as scenario_mod
    from cosim.core.master import Master

    sc = scenario_mod.load(scenario)
    if steps:
        sc = sc.with_changes(stop_time=sc.start_time + steps * ctrl.sample_time)
    if plant_kind == "fmu":
        from cosim.core.fmu import FmuComponent

        plant = FmuComponent(ROOT / "fmus" / "FourTank.fmu")
    else:
        from cosim.adapters.gru_plant import GRUPlant

        plant = GRUPlant(ctrl.mpc.model, y0=np.array([0.65, 0.65]))
    timed = TimedController(ctrl, others)
    result = Master(plant, timed, sc).run()
    if result.status != "ok":
        raise SystemExit(f"bench_mpc: the run failed: {result.reason}")
    return timed


def _p(a: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(a), q))


def compare_kernel(args: argparse.Namespace) -> None:
    """The compiled controller against the numpy baseline on the scenario."""
    plant = args.plant or ("fmu" if (ROOT / "fmus" / "FourTank.fmu").exists() else "model")
    variants = {"compiled": RobustMPCController(law=LAW),
                "numpy": RobustMPCController(law=LAW, kernel="numpy")}
    if variants["compiled"].mpc.fhocp.kernel is None:
        reason = variants["compiled"].mpc.fhocp.kernel_error
        raise SystemExit(f"bench_mpc: no compiled kernel ({reason})")
    wall = {k: [] for k in variants}
    cpu = {k: [] for k in variants}
    last = {}
    reference = None
    for r in range(args.rounds):
        for name, ctrl in variants.items():
            others = {}
            if name == "compiled" and args.reference and r == 0:
                others["ipopt"] = FHOCP.from_certificate(ctrl.mpc.cert, reference=FixedSetpoint(),
                                                         solver="ipopt",
                                                         ipopt_options={"tol": 1e-10,
                                                                        "max_iter": 500})
                others["ipopt"].setup()
            t = closed_loop(ctrl, Path(args.scenario), plant, args.steps, others)
            if others:
                reference = (t, list(ctrl.mpc.law.mpc.records))
            wall[name] += t.wall_ms
            cpu[name] += t.cpu_ms
            last[name] = t
            print(f"round {r + 1} {name:8s}: median {np.median(t.wall_ms):6.2f} ms, p99 "
                  f"{_p(t.wall_ms, 99):6.2f} ms (wall)", flush=True)
    n = len(last["compiled"].wall_ms)
    print(f"\nplant {plant}; {n} steps × {args.rounds} rounds each; model n="
          f"{variants['compiled'].mpc.model.n}, N={variants['compiled'].mpc.fhocp.N}; load average "
          f"{os.getloadavg()[0]:.2f} at the end")
    for metric, data in (("wall", wall), ("thread CPU", cpu)):
        c, b = data["compiled"], data["numpy"]
        print(f"{metric:10s} numpy    median {np.median(b):7.2f}  p99 {_p(b, 99):7.2f} ms")
        print(f"{metric:10s} compiled median {np.median(c):7.2f}  p99 {_p(c, 99):7.2f} ms")
        print(f"{metric:10s} speed-up median {np.median(b) / np.median(c):5.2f}x  p99 "
              f"{_p(b, 99) / _p(c, 99):5.2f}x   (targets >= 4x, >= 5x)")
    solve = {k: [r.result.solve_time * 1e3 for r in v.mpc.law.mpc.records]
             for k, v in variants.items()}
    c, b = solve["compiled"], solve["numpy"]
    print(f"FHOCP solve only (timings.csv solve_ms, last round): numpy median {np.median(b):.2f}"
          f" p99 {_p(b, 99):.2f} ms; compiled median {np.median(c):.2f} p99 {_p(c, 99):.2f} "
          f"ms; speed-up {np.median(b) / np.median(c):.2f}x, {_p(b, 99) / _p(c, 99):.2f}x")
    uc, un = np.array(last["compiled"].u), np.array(last["numpy"].u)
    k = int(np.argmax(np.any(np.abs(uc - un) > 1e-6, axis=1))) if np.any(
        np.abs(uc - un) > 1e-6) else len(uc)
    print(f"answers    the two closed loops apply the same inputs (within 1e-6) for the "
          f"first {k} of {len(uc)} steps")
    if reference is not None:
        report_reference(*reference)
    if args.plain:
        plain = FHOCP.from_certificate(variants["numpy"].mpc.cert, reference=FixedSetpoint(),
                                       formulation="multiple-shooting",
                                       ipopt_options=PLAIN_OPTIONS).setup()
        t = closed_loop(RobustMPCController(law=LAW), Path(args.scenario), plant, args.steps,
                        {"plain": plain})
        ms = [s[0] for s in t.solves["plain"]]
        print(f"plain      do-mpc-style multiple shooting (IPOPT): median {np.median(ms):.2f}, "
              f"p99 {_p(ms, 99):.2f} ms; {np.median(ms) / np.median(t.wall_ms):.0f}x the "
              "compiled controller step (median)")


def report_reference(timed: TimedController, recs: list) -> None:
    """The compiled controller's optima against tight IPOPT, and where they differ, whether
    the compiled answer is a local optimum (IPOPT restarted from it stays there)."""
    pairs = [(k, rec.result, (rec.result.cost - c) / (1 + abs(c))) for k, (rec, (_, ok, c))
             in enumerate(zip(recs, timed.solves["ipopt"], strict=False))
             if ok and rec.result.success]
    rel = np.array([d for _, _, d in pairs])
    print(f"answers    compiled optimum vs tight IPOPT (tol 1e-10, its own warm start) at "
          f"{len(rel)} steps where both converged: relative cost difference within 1e-6 at "
          f"{np.mean(np.abs(rel) <= 1e-6) * 100:.1f} %, median {np.median(rel):.1e}, "
          f"largest {np.max(rel):.1e} (compiled costlier), {np.min(rel):.1e} (cheaper)")
    ip = FHOCP.from_certificate(timed.ctrl.mpc.cert, reference=FixedSetpoint(), solver="ipopt",
                                ipopt_options={"tol": 1e-10, "max_iter": 500}).setup()
    # the same problem from the same start: tight IPOPT from the compiled solve's own initial
    # guess (cold multipliers), so that both solvers look for the optimum in the same place
    same = []
    for k, r, _ in pairs:
        rr = ip.solve(*timed.problems[k], u_init=timed.starts[k], warm=False)
        if rr.success:
            same.append((r.cost - rr.cost) / (1 + abs(rr.cost)))
    same_a = np.array(same)
    print(f"answers    compiled optimum vs tight IPOPT from the same initial guess at "
          f"{len(same_a)} steps where both converged: relative cost difference within 1e-6 "
          f"at {np.mean(np.abs(same_a) <= 1e-6) * 100:.1f} % ({int(np.sum(np.abs(same_a) > 1e-6))}"
          f" apart), median {np.median(same_a):.1e}, largest {np.max(same_a):.1e}, "
          f"{np.min(same_a):.1e}")
    apart = [(k, r) for k, r, d in pairs if abs(d) > 1e-6]
    if not apart:
        return
    # the FHOCP is nonconvex: two solvers may stop at different local optima. Restart tight
    # IPOPT from the compiled answer: if it stays, that answer is a local optimum too.
    stays = near = within = 0
    for k, r in apart:
        rr = ip.solve(*timed.problems[k], u_init=r.u, warm=False)
        d = (rr.cost - r.cost) / (1 + abs(r.cost))
        within += int(rr.success and abs(d) <= 1e-6)
        if rr.success and abs(d) <= 1e-7:
            stays += 1
        elif rr.success and abs(d) <= 1e-5:
            near += 1
    cheaper = sum(1 for _, _, d in pairs if d < -1e-6)
    print(f"answers      the {len(apart)} steps apart ({cheaper} with the compiled answer "
          f"cheaper): IPOPT restarted from the compiled answer stays there (within 1e-7) at "
          f"{stays}, ends within 1e-5 of it at {near}, moves away at "
          f"{len(apart) - stays - near}")
    print(f"answers    the compiled answer is a local optimum of the FHOCP to 1e-6 (tight "
          f"IPOPT agrees from its own warm start, or stays there when restarted from it) at "
          f"{(len(pairs) - len(apart) + within) / len(pairs) * 100:.1f} % of the steps")


def _equilibrium_output(model: Any, u: np.ndarray) -> np.ndarray:
    """The model's steady output [m] for the normalized input ``u``."""
    from controllers import gru
    from controllers.equilibrium import state_equilibrium

    x = state_equilibrium(model.params, u)
    return model.denormalize_y(np.asarray(gru.output(model.params, x), dtype=float))


#: casadi ``sqpmethod`` timers of one solve, in the order printed by ``--scaling``
SPLIT = (("QP", "t_wall_QP"), ("Hessian", "t_wall_nlp_hess_l"),
         ("Jacobian", "t_wall_nlp_jac_fg"), ("f, g", "t_wall_nlp_fg"))


class SplitController(TimedController):
    """:class:`TimedController` that also keeps, per step, the SQP's own timers (ms) of the
    step's solve, read after the timed part (casadi accumulates them over the solver's
    lifetime: the step's share is the difference)."""

    def __init__(self, ctrl: RobustMPCController) -> None:
        super().__init__(ctrl)
        self.split: list[tuple[float, ...]] = []
        self._last = np.zeros(len(SPLIT))

    def step(self, t: float, dt: float) -> None:
        super().step(t, dt)
        try:
            st = self.ctrl.mpc.fhocp._buffer[0].stats()
        except RuntimeError:   # no stats after an aborted solve: the step is left out
            return
        now = np.array([st.get(key, 0.0) * 1e3 for _, key in SPLIT])
        self.split.append((self.wall_ms[-1], *(now - self._last)))
        self._last = now


def scaling(args: argparse.Namespace) -> None:
    """Median step time for N in ``--horizons`` (n = 20) and n in ``--states`` (N = 15),
    random δISS GRUs.

    ``--rounds`` closed loops of each variant, alternating; a size's median is the median of
    the rounds' medians. For both variants, the split of the median steps (the steps within
    20 % of the median) into the SQP's QP, Hessian, Jacobian and f, g time, and the rest
    (Python, the answer check, the observer): the QP is the same qpOASES call in both."""
    folder = Path(tempfile.mkdtemp(prefix="bench-scaling-"))
    try:
        cases = _scaling_cases(args, folder)
        _scaling_rounds(cases, args.rounds)
        rows = [_scaling_report(case) for case in cases]
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    _scaling_fits(rows)


def _scaling_cases(args: argparse.Namespace, folder: Path) -> list[dict[str, Any]]:
    """One case per size: a certified random GRU (saved in ``folder``), five set-points it
    reaches, and its compiled and numpy controllers."""
    from controllers.certification import gain_design
    from cosim.core.scenario import Column, Event, Scenario
    from tests.controllers.random_gru import random_gru_model

    cols = (Column(2, "ref.h1", "ref", "h1"), Column(3, "ref.h2", "ref", "h2"))
    cases = []
    for n, N in [(20, N) for N in args.horizons] + [(n, 15) for n in args.states if n != 20]:
        model = random_gru_model(0, n=n)
        model.w_y_bar = 0.002
        # five set-points the model reaches: its equilibria for inputs inside the box
        setpoints = [_equilibrium_output(model, 0.5 * np.array([np.cos(a), np.sin(a)]))
                     for a in np.linspace(0.3, 2.8, 5)]
        events = [Event(1500.0 * j, 0, tuple(zip(cols, sp, strict=True)))
                  for j, sp in enumerate(setpoints)]
        sc = Scenario(Path("scaling.csv"), cols, (*events, Event(7500.0, 0, ())))
        targets = [model.normalize_y(sp) for sp in setpoints]
        theta, cert = gain_design.choose_gain_scale(model, targets, N=N)
        if theta is None:
            print(f"n={n}, N={N}: no certified design; skipped")
            continue
        path = folder / f"gru_{n}_{N}.json"
        model.L_z, model.L_r = cert.L_z, cert.L_r
        model.save(path)
        ctrls = {k: RobustMPCController(model=path, N=N, kernel=k, law=LAW)
                 for k in ("auto", "numpy")}
        cases.append({"n": n, "N": N, "y0": setpoints[0], "scenario": sc, "ctrls": ctrls,
                      "meds": {k: [] for k in ctrls}, "p99s": {k: [] for k in ctrls},
                      "split": {k: [] for k in ctrls}})
    return cases


def _scaling_rounds(cases: list[dict[str, Any]], rounds: int) -> None:
    """Round by round over every size and variant (the machine's drift over minutes hits
    all sizes alike instead of biasing the exponents): each round's median, p99 and split
    appended to its case."""
    from cosim.adapters.gru_plant import GRUPlant
    from cosim.core.master import Master

    for _ in range(max(1, rounds)):
        for case in cases:
            for kernel, ctrl in case["ctrls"].items():
                timed = SplitController(ctrl)
                result = Master(GRUPlant(ctrl.mpc.model, y0=case["y0"]), timed,
                                case["scenario"]).run()
                if result.status != "ok" or not timed.wall_ms:
                    raise SystemExit(f"bench_mpc: n={case['n']}, N={case['N']} "
                                     f"({kernel}): {result.reason}")
                case["meds"][kernel].append(float(np.median(timed.wall_ms)))
                case["p99s"][kernel].append(_p(timed.wall_ms, 99))
                case["split"][kernel] += timed.split


def _scaling_report(case: dict[str, Any]) -> tuple[Any, ...]:
    """Print one size's medians, p99s and splits; its row for the fits."""
    n, N, ctrls, meds = case["n"], case["N"], case["ctrls"], case["meds"]
    med = {k: (float(np.median(meds[k])), float(np.median(case["p99s"][k]))) for k in ctrls}
    fh = ctrls["auto"].mpc.fhocp
    variant = "numpy" if fh.kernel is None else next(
        (name for flag, name in (("-DGK_CONTRACT", "contract"), ("-DGK_BACKWARD", "backward"))
         if flag in fh.kernel.flags), "w")
    parts = {k: _median_split(case["split"][k], med[k][0]) for k in ctrls}
    print(f"n={n:3d} N={N:3d}: numpy median {med['numpy'][0]:7.2f} ms p99 "
          f"{med['numpy'][1]:7.2f}; compiled ({variant}) median {med['auto'][0]:6.2f}"
          f" ms p99 {med['auto'][1]:6.2f}; speed-up "
          f"{med['numpy'][0] / med['auto'][0]:.1f}x; rounds' medians "
          f"{' '.join(f'{v:.2f}' for v in meds['auto'])} ms", flush=True)
    for kernel, label in (("auto", "compiled"), ("numpy", "numpy")):
        print(f"    {label} median step: " + ", ".join(
            f"{name} {v:.2f}" for (name, _), v in zip(SPLIT, parts[kernel][:-1], strict=True))
              + f", rest {parts[kernel][-1]:.2f} ms", flush=True)
    return (n, N, *med["numpy"], *med["auto"], parts["numpy"][0], parts["auto"][0],
            meds["auto"])


def _scaling_fits(rows: list[tuple[Any, ...]]) -> None:
    """The growth exponents of the step and of its QP in N and in n, and the time one more
    stage (state) adds."""
    for label, sel, col in (("N (n = 20)", [r for r in rows if r[0] == 20], 1),
                            ("n (N = 15)", [r for r in rows if r[1] == 15], 0)):
        if len(sel) >= 2:
            x = np.log([r[col] for r in sel])
            for name, j in (("numpy", 2), ("compiled", 4)):
                slope = np.polyfit(x, np.log([r[j] for r in sel]), 1)[0]
                print(f"median grows as {label.split()[0]}^{slope:.2f} ({name}, {label})")
            per_round = [np.polyfit(x, np.log([r[8][k] for r in sel]), 1)[0]
                         for k in range(min(len(r[8]) for r in sel))]
            print(f"  compiled, round by round: "
                  f"{', '.join(f'{label.split()[0]}^{v:.2f}' for v in per_round)}")
            for name, j in (("numpy", 6), ("compiled", 7)):
                slope = np.polyfit(x, np.log([r[j] for r in sel]), 1)[0]
                print(f"the QP in its median step grows as {label.split()[0]}^{slope:.2f} "
                      f"({name}, {label})")
            # what one more stage (state) costs: the time added between the smallest and the
            # largest size, per unit of size
            lo, hi = sel[0], sel[-1]
            added = {name: (hi[j] - lo[j]) / (hi[col] - lo[col])
                     for name, j in (("numpy", 2), ("compiled", 4))}
            print(f"median step time added per unit of {label.split()[0]} from "
                  f"{lo[col]} to {hi[col]}: numpy {added['numpy']:.3f} ms, compiled "
                  f"{added['compiled']:.3f} ms ({added['numpy'] / added['compiled']:.1f}x less)")


def _median_split(split: list[tuple[float, ...]], median: float) -> np.ndarray:
    """QP, Hessian, Jacobian, f, g and the rest (ms) of the steps within 20 % of the median
    step (all steps when none is)."""
    a = np.asarray(split)
    if not len(a):
        return np.full(len(SPLIT) + 1, np.nan)
    sel = a[np.abs(a[:, 0] - median) <= 0.2 * median]
    parts = np.median(sel if len(sel) else a, axis=0)
    return np.append(parts[1:], parts[0] - float(np.sum(parts[1:])))


def clip_variants(args: argparse.Namespace) -> None:
    """The Hessian's eigenvalue clipping: the own eigenpairs below the margin (Householder, QL
    without vectors, inverse iteration) against LAPACK dsyevr's, on Hessian-like matrices
    (eigenvalues 0.05 … 6e4, three below the margin, as the paper scenario's ~2.4 per
    decomposition), for N m = 30 … 120."""
    from controllers.kernel import compiled_kernel as ck
    from tests.controllers.kernel.test_compiled_kernel import random_fhocp

    saved = ck.LAPACK_EIG_MIN_NU
    try:
        for N in (15, 24, 30, 45, 60):
            fh = random_fhocp(20, N, seed=1, kernel="numpy")
            us, out = {}, {}
            for name, thr in (("own", 10**6), ("dsyevr", 1)):
                ck.LAPACK_EIG_MIN_NU = thr
                k = ck.build(ck.KernelProblem(fh.params, fh.N, fh.Q, fh.R, fh.DUo, fh.s, 1e-2,
                                                LUo=fh.LUo))
                if k is None or (name == "dsyevr") != ("-DGK_LAPACK_EIG" in k.flags):
                    print(f"N m = {N * fh.m}: no {name} kernel ({ck.last_error})")
                    return
                ws = k.workspace()
                rng = np.random.default_rng(0)
                q, _ = np.linalg.qr(rng.normal(size=(k.nw - 1, k.nw - 1)))
                lam = np.geomspace(0.05, 6e4, k.nw - 1)
                lam[:3] = [-3.0, -0.1, 0.005]
                H0 = np.zeros((k.nw, k.nw))
                H0[:-1, :-1] = (q * lam) @ q.T
                H0[-1, -1] = 1.0
                t0 = time.perf_counter()
                for _ in range(500):
                    H = ws.clip(H0)     # a copy of H0, clipped (the copy: ~1 µs)
                us[name], out[name] = (time.perf_counter() - t0) / 500 * 1e6, H.copy()
            print(f"N m = {N * fh.m:3d}: own {us['own']:7.1f} µs, dsyevr {us['dsyevr']:7.1f} µs "
                  f"({us['own'] / us['dsyevr']:.2f}x); clipped matrices differ by "
                  f"{np.max(np.abs(out['own'] - out['dsyevr'])) / 6e4:.1e} (relative)")
    finally:
        ck.LAPACK_EIG_MIN_NU = saved
    print(f"the kernel uses dsyevr from N m = {saved}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2, help="runs of each variant (alternating)")
    ap.add_argument("--steps", type=int, default=None, help="stop after this many steps")
    ap.add_argument("--plant", choices=("fmu", "model"), default=None,
                    help="plant (default: the FMU when built, else the GRU model)")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "paper_steps.csv"))
    ap.add_argument("--reference", action="store_true",
                    help="solve every FHOCP of the first compiled run with tight IPOPT too")
    ap.add_argument("--scaling", action="store_true", help="the N and n scaling instead")
    ap.add_argument("--horizons", type=int, nargs="+", default=[15, 30, 60],
                    help="--scaling: the horizons N timed at n = 20")
    ap.add_argument("--states", type=int, nargs="+", default=[20, 40, 80],
                    help="--scaling: the state sizes n timed at N = 15")
    ap.add_argument("--plain", action="store_true",
                    help="also time the do-mpc-style multiple-shooting baseline")
    ap.add_argument("--clip", action="store_true",
                    help="the eigenvalue clipping's two variants instead (own, dsyevr)")
    args = ap.parse_args(argv)
    if args.clip:
        clip_variants(args)
    elif args.scaling:
        scaling(args)
    else:
        compare_kernel(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
