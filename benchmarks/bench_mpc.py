"""Speed of the robust MPC controller step (observer + FHOCP) against a plain formulation.

Runs the paper scenario (``scenarios/paper_steps.csv``) in closed loop with the plant FMU
(``fmus/FourTank.fmu`` through :class:`cosim.fmu.FmuComponent`; the GRU model itself as
plant when no FMU is built) and the ``robust-mpc`` controller, timing every controller step.
In the same run, at every step, the same FHOCP (same ``x̂_k``, ``ê_o,k``, ``x̄``, ``ū``, ``α``)
is solved by the plain formulation do-mpc would build: multiple shooting, exact Hessian,
IPOPT defaults, warm start with the previous solution (primal only). Prints median / p99
times, the speed ratio and how well the optimal costs agree.

Usage::

    .venv/bin/python benchmarks/bench_mpc.py [--steps N] [--plant fmu|model] [--quiet]
        [--no-baseline] [--no-governor] [--solver ipopt|sqp]

The controller runs with its default solver, casadi's ``sqpmethod`` (``--solver sqp``), and at
every step the same FHOCP is also solved with IPOPT on the same single-shooting callbacks (its
own warm start) to compare the optimal costs and times (``--no-reference`` skips it);
``--solver ipopt`` runs the controller with IPOPT instead.

Targets (issue 5): median ≤ 5 ms, p99 ≤ 25 ms per controller step, ≥ 10× faster than the
plain formulation, optimal costs agreeing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.fhocp import FHOCP  # noqa: E402
from controllers.mpc_controller import RobustMPCController  # noqa: E402
from cosim.component import Component  # noqa: E402

#: The plain baseline may take seconds to declare infeasibility; cap it so the run ends.
BASELINE_OPTIONS = {"max_wall_time": 2.0}


class TimedController(Component):
    """Wraps the controller: times each ``step`` and solves the baseline FHOCP alongside."""

    def __init__(self, ctrl: RobustMPCController, baseline: FHOCP | None,
                 reference: FHOCP | None = None) -> None:
        self.ctrl = ctrl
        self.baseline = baseline
        self.reference = reference
        self.ref: list[tuple[float, bool, str, float]] = []  # ms, success, status, cost
        self.name, self.inputs, self.outputs = ctrl.name, ctrl.inputs, ctrl.outputs
        self.direct_feedthrough = True
        self.sample_time, self.bounds = ctrl.sample_time, ctrl.bounds
        self.step_ms: list[float] = []
        self.base: list[tuple[float, bool, str, float]] = []  # ms, success, status, cost
        self._u_prev: np.ndarray | None = None

    def setup(self, t0: float) -> None:
        self.ctrl.setup(t0)

    def set_inputs(self, values: dict[str, float]) -> None:
        self.ctrl.set_inputs(values)

    def get_outputs(self) -> dict[str, float]:
        return self.ctrl.get_outputs()

    def diagnostics(self) -> dict[str, float]:
        return self.ctrl.diagnostics()

    def step(self, t: float, dt: float) -> None:
        t0 = time.perf_counter()
        self.ctrl.step(t, dt)
        self.step_ms.append((time.perf_counter() - t0) * 1e3)
        mpc = self.ctrl.mpc
        rec = mpc.records[-1]
        if self.reference is not None:
            r = self.reference.solve(rec.x_hat, rec.e_o, mpc.x_bar, mpc.u_bar, mpc.alpha)
            self.ref.append((r.solve_time * 1e3, r.success, r.status, r.cost))
        if self.baseline is None:
            return
        res = self.baseline.solve(rec.x_hat, rec.e_o, mpc.x_bar, mpc.u_bar, mpc.alpha,
                                  u_init=self._u_prev, warm=False)
        if res.success:
            self._u_prev = res.u
        self.base.append((res.solve_time * 1e3, res.success, res.status, res.cost))


def stats(ms: list[float]) -> str:
    a = np.asarray(ms)
    return (f"median {np.median(a):7.2f}  p90 {np.percentile(a, 90):7.2f}  "
            f"p99 {np.percentile(a, 99):7.2f}  max {np.max(a):8.2f} ms")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=None, help="stop after this many steps")
    ap.add_argument("--plant", choices=("fmu", "model"), default=None,
                    help="plant (default: the FMU when built, else the GRU model)")
    ap.add_argument("--no-baseline", action="store_true", help="time the controller only")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "paper_steps.csv"))
    ap.add_argument("--no-governor", action="store_true",
                    help="the paper's controller: no reference governor after set-point steps")
    ap.add_argument("--solver", choices=("ipopt", "sqp"), default="sqp",
                    help="NLP solver of the controller's FHOCP (default sqp: casadi sqpmethod "
                         "+ qpOASES, with IPOPT solving the same problems alongside for "
                         "comparison; ipopt: the previous default)")
    ap.add_argument("--no-reference", action="store_true",
                    help="with --solver sqp: do not solve with IPOPT alongside (timing only)")
    ap.add_argument("--sqp-options", default="{}",
                    help="JSON overrides of controllers.solver_settings.SQP_OPTIONS, e.g. "
                         "'{\"tol_du\": 1e-4}'")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)

    from cosim import scenario as scenario_mod
    from cosim.master import Master

    ctrl = RobustMPCController(governor=not args.no_governor)
    cert = ctrl.cert
    reference = None
    if args.solver == "sqp":
        import json

        ctrl.fhocp.solver = "sqp"
        ctrl.fhocp.sqp_options.update(json.loads(args.sqp_options))
        if not args.no_reference:
            reference = FHOCP.from_certificate(cert, solver="ipopt").setup()
    else:
        ctrl.fhocp.solver = "ipopt"
    ctrl.fhocp.setup()
    baseline = None if args.no_baseline else FHOCP.from_certificate(
        cert, formulation="multiple-shooting", ipopt_options=BASELINE_OPTIONS).setup()
    timed = TimedController(ctrl, baseline, reference)
    sc = scenario_mod.load(args.scenario)
    fmu = ROOT / "fmus" / "FourTank.fmu"
    kind = args.plant or ("fmu" if fmu.exists() else "model")
    y0 = np.array([0.65, 0.65])  # the paper scenario's first set-point
    if kind == "fmu":
        from cosim.fmu import FmuComponent
        plant = FmuComponent(fmu)
    else:
        from controllers.model_plant import GRUPlant
        plant = GRUPlant(ctrl.model, y0=y0)
    master = Master(plant, timed, sc)
    total = round(sc.stop_time / ctrl.sample_time)
    limit = min(total, args.steps) if args.steps else total
    bar = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=limit, unit="step", desc="bench_mpc")

    class _Stop(Exception):
        pass

    def on_step(k: int) -> None:
        if bar is not None:
            bar.update(1)
        if k + 1 >= limit:
            raise _Stop

    try:
        master.run(on_step=on_step)
    except _Stop:
        pass
    finally:
        if bar is not None:
            bar.close()
        plant.terminate()
    s = ctrl.summary()
    print(f"plant: {kind}; steps: {len(timed.step_ms)}; model n={ctrl.model.n}, N={cert.N}; "
          f"load average {os.getloadavg()[0]:.2f} (1 min) at the end")
    label = "IPOPT" if args.solver == "ipopt" else "sqpmethod + qpOASES"
    print(f"fast   (single shooting, exact Hessian, {label} warm start), controller step: "
          f"{stats(timed.step_ms)}")
    print(f"       FHOCP solve only: median {s['solve_ms_median']:.2f}, p99 "
          f"{s['solve_ms_p99']:.2f} ms; iterations median {s['iterations_median']:.0f}; "
          f"failures {s['failures']} {s['failures_by_status']}; fallbacks {s['fallbacks']}; "
          f"suboptimal (capped, feasible) {s['suboptimal_steps']}; governor steps "
          f"{s['governor_steps']} (held {s['governor_holds']})")
    if timed.ref:
        rms = [r[0] for r in timed.ref]
        sms = [r.result.solve_time * 1e3 for r in ctrl.mpc.records]
        print(f"ipopt  same FHOCPs, default IPOPT solver alongside: {stats(rms)}")
        print(f"       FHOCP solve ms, sqp vs ipopt: median {np.median(sms):.2f} vs "
              f"{np.median(rms):.2f}, p99 {np.percentile(sms, 99):.2f} vs "
              f"{np.percentile(rms, 99):.2f}")
        rel = [(rec.result.cost - r[3]) / (1.0 + abs(r[3]))
               for rec, r in zip(ctrl.mpc.records, timed.ref, strict=False)
               if rec.result.success and r[1]]
        n_ref = sum(r[1] for r in timed.ref)
        if rel:
            ra = np.asarray(rel)
            print(f"costs  sqp vs ipopt, both optimal at {len(ra)} of {n_ref} ipopt-optimal "
                  f"steps: within 1e-6 {np.mean(np.abs(ra) <= 1e-6) * 100:.1f} %, max "
                  f"{np.max(ra):.1e}, min {np.min(ra):.1e}")
    if timed.base:
        bms = [b[0] for b in timed.base]
        print(f"plain  (multiple shooting, do-mpc style IPOPT):                  {stats(bms)}")
        fast_ms = np.asarray(timed.step_ms[: len(bms)])
        print(f"ratio  plain / fast: median {np.median(bms) / np.median(fast_ms):.1f}x, "
              f"p99 {np.percentile(bms, 99) / np.percentile(fast_ms, 99):.1f}x, "
              f"total {np.sum(bms) / np.sum(fast_ms):.1f}x")
        both, rel = 0, []
        only_fast = only_base = 0
        for rec, b in zip(ctrl.mpc.records, timed.base, strict=False):
            if rec.result.success and b[1]:
                both += 1
                rel.append((rec.result.cost - b[3]) / (1.0 + abs(b[3])))
            elif rec.result.success:
                only_fast += 1
            elif b[1]:
                only_base += 1
        rel_a = np.asarray(rel)
        if both:
            print(f"costs  both optimal at {both} steps: (fast − plain)/(1 + |plain|) median "
                  f"{np.median(rel_a):.1e}, max {np.max(rel_a):.1e}, min {np.min(rel_a):.1e};"
                  f" within 1e-6: {np.mean(np.abs(rel_a) <= 1e-6) * 100:.1f} %")
        print(f"       solved by fast only: {only_fast}, by plain only: {only_base}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
