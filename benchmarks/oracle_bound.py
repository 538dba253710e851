"""How much better than the PI any causal controller can be: an IAE oracle for the example
heater and furnace, and the MPC's share of that room.

    python benchmarks/oracle_bound.py WALKTHROUGH_DIR [--horizon N]

``WALKTHROUGH_DIR`` is what ``examples/own_plant.py --plant heater|furnace --out DIR`` wrote
(its scenario, plant FMU and closed loops of the robust MPC and the PI). The oracle knows what
no real controller knows: the plant's equations and parameters exactly (the example script's
constants, the FMU's start values), and its true state, which both plants expose as their
outputs (the zone temperatures). It does not know future set-points. Each sample it solves::

    min_{X, U}  Σ_{i=1}^{N} Σ_j |y_{j,i} − r_j| / (box width of y_j)
    s.t.        X_0 = x_k,  X_{i+1} = F(X_i, u_{i−K}, d_k),  u_i in the input box

(``K`` an input's dead time, ``u_{i−K}`` for ``i < K`` the inputs already applied; ``d_k``
the measured disturbances now, held over the horizon: the oracle knows the present, not the
future) the summed IAE of ``examples/own_plant.py`` over the horizon (the sampled IAE of
:mod:`cosim.core.kpis`, zero-order hold), with ``F`` the plant's own RK4 over one sample (the
same substeps as the FMU's integrator, ``plant_base.py``). Multiple shooting, the absolute
values as slack variables, IPOPT warm-started from the previous plan; every answer is checked
without IPOPT (shooting defects, input box, slacks), a failed one replaced by a cold start,
else by the previous plan shifted (counted in ``failures``). It is a benchmark reference, kept
out of the shipped packages like ``oracle_nmpc.py``.

``heater_dead_time`` (its power 40 s late, its ambient temperature measured) and
``furnace_load`` (its product throughput measured) are the plants of
``disturbance_campaign.py``, which runs this oracle on each of its campaign's runs
(``--oracle``: the drawn heat capacity, set-points and disturbance steps).

It prints the oracle's summed IAE over the PI's (the best ratio a causal controller could
reach on this scenario, up to the horizon and the solver's local optima) beside the MPC's,
and the share of the reachable improvement the MPC takes: ``(PI − MPC) / (PI − oracle)``.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.problem import ControlProblem  # noqa: E402
from cosim.core.component import Component, Signal  # noqa: E402
from cosim.core.kpis import summed  # noqa: E402

#: Largest shooting defect [K], input-box excess [normalised] and slack shortfall an answer
#: may have.
CHECK_TOL = 1e-6
IPOPT_OPTIONS: dict[str, Any] = {"print_level": 0, "tol": 1e-9, "max_iter": 500, "sb": "yes"}
#: Default horizons [samples]: a few of the slowest time constants (heater 670 s, furnace's
#: common mode 20-30 min, Ts = 20 s).
HORIZONS = {"heater": 60, "furnace": 120, "heater_dead_time": 60, "furnace_load": 120}


def constants(plant: str) -> dict[str, float]:
    """The numbers ``fmus/examples/<plant>/<plant>.py`` assigns (``C, UA0, UA1 = ...``) at
    module level or in a class body, over those of ``fmus/examples/plant_base.py`` (the
    furnaces' ``C, UA, K, E``), read from their sources: importing the plant here would shadow
    the module of that name the pythonfmu plant loads in this process."""
    out: dict[str, float] = {}
    for path in (ROOT / "fmus" / "examples" / "plant_base.py",
                 ROOT / "fmus" / "examples" / plant / f"{plant}.py"):
        tree = ast.parse(path.read_text())
        for node in tree.body:
            body = node.body if isinstance(node, ast.ClassDef) else [node]
            for stmt in body:
                out.update(_assigned_numbers(stmt))
    return out


def _assigned_numbers(node: ast.stmt) -> dict[str, float]:
    """``{name: number}`` of an assignment of numeric constants (one or a tuple)."""
    if not isinstance(node, ast.Assign) or not isinstance(node.targets[0], ast.Tuple | ast.Name):
        return {}
    names = node.targets[0].elts if isinstance(node.targets[0], ast.Tuple) else [node.targets[0]]
    values = node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
    return {name.id: float(value.value) for name, value in zip(names, values, strict=False)
            if isinstance(name, ast.Name) and isinstance(value, ast.Constant)
            and isinstance(value.value, int | float)}


def heater_rhs(p: Mapping[str, float]) -> Callable[[Any, Any, Any], Any]:
    """``dT/dt`` of ``fmus/examples/heater/heater.py`` (casadi), its parameters ``p``."""
    k = constants("heater")
    C = p["C_factor"] * k["C"]

    def rhs(x: Any, u: Any, _d: Any) -> Any:
        d = x[0] - p["T_amb"]
        return (u[0] - (k["UA0"] + k["UA1"] * ca.fmax(d, 0.0)) * d) / C
    return rhs


def heater_dead_time_rhs(p: Mapping[str, float]) -> Callable[[Any, Any, Any], Any]:
    """``dT/dt`` of ``fmus/examples/heater_dead_time/heater_dead_time.py`` (casadi): ``u`` the
    power as the vessel sees it (applied 40 s before), ``d`` the ambient temperature."""
    k = constants("heater_dead_time")
    C = p["C_factor"] * k["C"]

    def rhs(x: Any, u: Any, d: Any) -> Any:
        dt = x[0] - d[0]
        return (u[0] - (k["UA0"] + k["UA1"] * ca.fmax(dt, 0.0)) * dt) / C
    return rhs


def furnace_rhs(p: Mapping[str, float]) -> Callable[[Any, Any, Any], Any]:
    """``dT1/dt, dT2/dt`` of ``fmus/examples/furnace/furnace.py`` (casadi)."""
    f = constants("furnace")
    amb, k, c = p["T_amb"] + 273.15, p["K_factor"] * f["K"], p["C_factor"] * f["C"]

    def rhs(x: Any, u: Any, _d: Any) -> Any:
        q12 = k * (x[0] - x[1])
        loss = [f["UA"] * (x[i] - p["T_amb"]) + f["E"] * ((x[i] + 273.15) ** 4 - amb ** 4)
                for i in range(2)]
        return ca.vertcat(u[0] - loss[0] - q12, u[1] - loss[1] + q12) / c
    return rhs


def furnace_load_rhs(p: Mapping[str, float]) -> Callable[[Any, Any, Any], Any]:
    """``dT1/dt, dT2/dt`` of ``fmus/examples/furnace_load/furnace_load.py`` (casadi): ``d``
    the product throughput [kg/h]."""
    f = constants("furnace_load")
    amb, k, c = p["T_amb"] + 273.15, p["K_factor"] * f["K"], p["C_factor"] * f["C"]

    def rhs(x: Any, u: Any, d: Any) -> Any:
        g = d[0] * f["CP"] / 3600.0
        q12 = k * (x[0] - x[1])
        loss = [f["UA"] * (x[i] - p["T_amb"]) + f["E"] * ((x[i] + 273.15) ** 4 - amb ** 4)
                for i in range(2)]
        return ca.vertcat(u[0] - loss[0] - q12 - g * (x[0] - p["T_amb"]),
                          u[1] - loss[1] + q12 - g * (x[1] - x[0])) / c
    return rhs


#: plant -> (its equations, its parameters' names, RK4 substep [s] of its FMU)
PLANTS = {"heater": (heater_rhs, ("T_amb", "C_factor"), 2.0),
          "furnace": (furnace_rhs, ("T_amb", "K_factor", "C_factor"), 2.0),
          "heater_dead_time": (heater_dead_time_rhs, ("C_factor",), 2.0),
          "furnace_load": (furnace_load_rhs, ("T_amb", "K_factor", "C_factor"), 2.0)}


def rk4_map(rhs: Callable[[Any, Any, Any], Any], n: int, m: int, nd: int, Ts: float,
            substep: float) -> ca.Function:
    """``F(x, u, d) → x⁺``: RK4 over ``Ts`` in steps of at most ``substep``, ``u`` (as the
    plant sees it) and the disturbances ``d`` held."""
    x, u, d = ca.SX.sym("x", n), ca.SX.sym("u", m), ca.SX.sym("d", nd)
    steps = int(np.ceil(Ts / substep - 1e-9))
    dt, z = Ts / steps, x
    for _ in range(steps):
        k1 = rhs(z, u, d)
        k2 = rhs(z + 0.5 * dt * k1, u, d)
        k3 = rhs(z + 0.5 * dt * k2, u, d)
        k4 = rhs(z + dt * k3, u, d)
        z = z + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [x, u, d], [z])


class IAEOracle:
    """The FHOCP of the module docstring, built once and solved per sample.

    Parameters
    ----------
    F : casadi.Function
        The plant's map over one sample, ``x⁺ = F(x, u, d)`` in physical units (states = the
        problem's outputs, in their order; ``u`` the inputs as the plant sees them, ``d`` the
        measured disturbances).
    problem : ControlProblem
        Its inputs' ``delay`` are the dead times ``K``.
    horizon : int
    """

    def __init__(self, F: ca.Function, problem: ControlProblem, horizon: int) -> None:
        self.F, self.N, self.n, self.m = F, horizon, problem.p, problem.m
        self.nd = len(problem.disturbances)
        self.delays = tuple(int(c.delay) for c in problem.inputs)
        self.K = max(self.delays, default=0)
        lo, hi = np.array(problem.input_bounds).T
        self.u_lo, self.u_hi = lo, hi
        self.width = np.array([c.max - c.min for c in problem.outputs])
        n, m, N, nd, K = self.n, self.m, horizon, self.nd, self.K
        X, U, E = ca.SX.sym("X", n, N + 1), ca.SX.sym("U", m, N), ca.SX.sym("E", n, N)
        p = ca.SX.sym("p", 2 * n + nd + K * m)    # x_k, r, d_k, the last K inputs (oldest first)
        past = ca.reshape(p[2 * n + nd:], m, K) if K else ca.SX(m, 0)
        seen = ca.vertcat(*(ca.horzcat(past[j, K - kj:], U[j, :N - kj]) if kj else U[j, :]
                            for j, kj in enumerate(self.delays)))
        d = p[2 * n:2 * n + nd]
        err = X[:, 1:] - ca.repmat(p[n:2 * n], 1, N)
        defects = [X[:, i + 1] - F(X[:, i], seen[:, i], d) for i in range(N)]
        g = ca.vertcat(ca.vec(X[:, 0] - p[:n]), *defects, ca.vec(E - err), ca.vec(E + err))
        w = ca.diag(ca.DM(1.0 / self.width))
        nlp = {"x": ca.vertcat(ca.vec(X), ca.vec(U), ca.vec(E)), "p": p,
               "f": ca.sum1(ca.sum2(w @ E)), "g": g}
        self.solver = ca.nlpsol("iae_oracle", "ipopt", nlp,
                                {"ipopt": IPOPT_OPTIONS, "print_time": False})
        self.seen = ca.Function("seen", [U, p], [seen])
        self.nX, self.nU = n * (N + 1), m * N
        nw = self.nX + self.nU + n * N
        self.lbx, self.ubx = np.full(nw, -np.inf), np.full(nw, np.inf)
        self.lbx[self.nX:self.nX + self.nU] = np.tile(lo, N)
        self.ubx[self.nX:self.nX + self.nU] = np.tile(hi, N)
        neq = n * (N + 1)                       # equalities, then E ≥ ±err
        self.lbg = np.zeros(neq + 2 * n * N)
        self.ubg = np.concatenate([np.zeros(neq), np.full(2 * n * N, np.inf)])

    def parameters(self, x: np.ndarray, r: np.ndarray, d: np.ndarray,
                   past: np.ndarray) -> np.ndarray:
        """The NLP's ``p``: state, set-points, disturbances and the last ``K`` inputs
        (``K × m``, oldest first)."""
        return np.concatenate([x, r, d, np.asarray(past, dtype=float).reshape(-1)])

    def rollout(self, x: np.ndarray, U: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """States ``(N+1) × n`` of the inputs ``U`` (``N × m``) from ``x`` (``pv``: the
        disturbances and past inputs of :meth:`parameters`)."""
        seen = np.asarray(self.seen(U.T, pv)).T
        d = pv[2 * self.n:2 * self.n + self.nd]
        X = [np.asarray(x, dtype=float)]
        for u in seen:
            X.append(np.asarray(self.F(X[-1], u, d)).ravel())
        return np.array(X)

    def solve(self, pv: np.ndarray, U0: np.ndarray) -> tuple[np.ndarray, bool]:
        """The plan's inputs ``N × m`` from the start ``U0`` at the parameters ``pv``
        (:meth:`parameters`), and whether it passed the checks."""
        x, r = pv[:self.n], pv[self.n:2 * self.n]
        X0 = self.rollout(x, U0, pv)
        E0 = np.abs(X0[1:] - r)
        w0 = np.concatenate([X0.ravel(), U0.ravel(), E0.ravel()])
        sol = self.solver(x0=w0, p=pv, lbx=self.lbx, ubx=self.ubx,
                          lbg=self.lbg, ubg=self.ubg)
        w = np.asarray(sol["x"]).ravel()
        X = w[:self.nX].reshape(self.N + 1, self.n)
        U = w[self.nX:self.nX + self.nU].reshape(self.N, self.m)
        E = w[self.nX + self.nU:].reshape(self.N, self.n)
        ok = bool(self.solver.stats()["success"]) and self._check(pv, X, U, E)
        return U, ok

    def _check(self, pv: np.ndarray, X: np.ndarray, U: np.ndarray, E: np.ndarray) -> bool:
        if not all(np.all(np.isfinite(a)) for a in (X, U, E)):
            return False
        x, r = pv[:self.n], pv[self.n:2 * self.n]
        excess = np.max(np.maximum(self.u_lo - U, U - self.u_hi) / (self.u_hi - self.u_lo))
        defect = np.max(np.abs(self.rollout(x, U, pv) - X)) / max(1.0, float(np.max(np.abs(X))))
        shortfall = np.max(np.abs(X[1:] - r) - E)   # a slack below its |error|
        return bool(max(excess, defect, shortfall) <= CHECK_TOL)


class OracleController(Component):
    """The IAE oracle as a co-simulation controller (module docstring).

    Parameters
    ----------
    plant : {"heater", "furnace", "heater_dead_time", "furnace_load"}
    fmu : path
        The plant FMU: its parameters' values are the start values of its modelDescription,
        unless ``parameters`` gives them; so are the inputs it has seen before the run (a
        dead time's first samples).
    problem : path
        The plant's problem file.
    horizon : int, optional
        ``N`` (default :data:`HORIZONS`).
    parameters : mapping, optional
        Parameter values that differ from the FMU's start values (a campaign's draw).
    """

    name = "oracle"
    direct_feedthrough = True

    def __init__(self, plant: str, fmu: str | Path, problem: str | Path,
                 horizon: int | None = None,
                 parameters: Mapping[str, float] | None = None) -> None:
        from controllers.problem_file import load
        from cosim.core.fmu_archive import read_model_description

        rhs_of, names, substep = PLANTS[plant]
        self.problem = pr = load(problem)
        md = read_model_description(fmu)
        start = {v.name: float(v.start) for v in md.modelVariables if v.start is not None
                 and v.name in (*names, *(c.variable or c.name for c in pr.inputs))}
        params = {**start, **(parameters or {})}
        F = rk4_map(rhs_of(params), pr.p, pr.m, len(pr.disturbances), pr.Ts, substep)
        self.ocp = IAEOracle(F, pr, horizon or HORIZONS[plant])
        #: what the plant applied before the run (its inputs' start values)
        self.u_start = np.array([start.get(c.variable or c.name, 0.5 * (c.min + c.max))
                                 for c in pr.inputs])
        self.d_default = {c.name: c.offset for c in pr.disturbances}
        self.sample_time = pr.Ts
        self.bounds = pr.bounds()
        self.inputs = (*(Signal(c.name, c.unit) for c in pr.outputs),
                       *(Signal(f"ref.{c.name}", c.unit) for c in pr.outputs),
                       *(Signal(f"dist.{c.name}", c.unit) for c in pr.disturbances))
        self.outputs = tuple(Signal(c.name, c.unit) for c in pr.inputs)
        self._values: dict[str, float] = {}
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        """Forget the previous run."""
        self._U: np.ndarray | None = None
        self._past = np.tile(self.u_start, (self.ocp.K, 1))   # K × m, oldest first
        self._next: np.ndarray | None = None   # the plan's state one sample on
        self.failures = self.cold_starts = self.steps = 0
        self.solve_ms: list[float] = []
        self.pred_err: list[float] = []

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._values.update(values)

    def step(self, t: float, dt: float) -> None:
        """Solve from the measured state (the outputs), the disturbances measured now and
        the inputs still on their way; hold the plan's first input."""
        pr, ocp = self.problem, self.ocp
        x = np.array([self._values[o] for o in pr.output_names])
        r = np.array([self._values[f"ref.{o}"] for o in pr.output_names])
        d = np.array([self._values.get(f"dist.{c.name}", self.d_default[c.name])
                      for c in pr.disturbances])
        if self._next is not None:   # the model against the plant, one sample on
            self.pred_err.append(float(np.max(np.abs(self._next - x))))
        pv = ocp.parameters(x, r, d, self._past)
        t0 = time.perf_counter()
        middle = np.tile(0.5 * (ocp.u_lo + ocp.u_hi), (ocp.N, 1))
        warm = None if self._U is None else np.vstack([self._U[1:], self._U[-1:]])
        U, ok = ocp.solve(pv, warm if warm is not None else middle)
        if not ok and warm is not None:
            self.cold_starts += 1
            U, ok = ocp.solve(pv, middle)
        if not ok:
            self.failures += 1
            U = warm if warm is not None else middle
        self.solve_ms.append((time.perf_counter() - t0) * 1e3)
        self.steps += 1
        self._U = np.clip(U, ocp.u_lo, ocp.u_hi)   # IPOPT's bounds are relaxed by ~1e-8
        self._next = ocp.rollout(x, self._U, pv)[1]
        if ocp.K:
            self._past = np.vstack([self._past[1:], self._U[:1]])

    def get_outputs(self) -> dict[str, float]:
        u = self._U[0] if self._U is not None else 0.5 * (self.ocp.u_lo + self.ocp.u_hi)
        return {c.name: float(v) for c, v in zip(self.problem.inputs, u, strict=True)}

    def summary(self) -> dict:
        ms = np.asarray(self.solve_ms or [np.nan])
        return {"horizon": self.ocp.N, "steps": self.steps, "failures": self.failures,
                "cold_starts": self.cold_starts, "solve_ms_median": float(np.median(ms)),
                "prediction_error_max": max(self.pred_err, default=0.0)}


def main(argv: list[str] | None = None) -> int:
    import cosim

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("walkthrough", type=Path,
                        help="the --out folder of examples/own_plant.py (heater or furnace)")
    parser.add_argument("--horizon", type=int, default=None,
                        help="oracle horizon [samples] (default: heater 60, furnace 120)")
    args = parser.parse_args(argv)
    d = args.walkthrough
    report = json.loads((d / "walkthrough.json").read_text())
    plant = report["plant"]
    if plant not in PLANTS:
        raise SystemExit(f"oracle_bound: {plant!r} has no oracle here ({', '.join(PLANTS)})")
    fmu = next((d / "fmu").glob("*.fmu"))
    problem = ROOT / "fmus" / "examples" / plant / "problem.toml"
    horizon = args.horizon or HORIZONS[plant]
    t0 = time.perf_counter()
    run = cosim.run(d / "scenario.csv", plant=fmu, controller="oracle_bound:OracleController",
                    options={"plant": plant, "fmu": str(fmu), "problem": str(problem),
                             "horizon": horizon}, problem=problem)
    if run.status != "ok":
        raise SystemExit(f"oracle_bound: the oracle's run {run.status}: {run.reason}")
    iae = {"oracle": summed(run.summary, "iae")}
    for name in ("pi", "robust-mpc"):
        iae[name] = summed(json.loads((d / "runs" / name / "summary.json").read_text()), "iae")
    o, pi, mpc = iae["oracle"], iae["pi"], iae["robust-mpc"]
    info = run.summary.get("controller_summary", {})
    print(f"{plant}: oracle (N = {horizon}, {time.perf_counter() - t0:.0f} s, "
          f"{info.get('failures', '?')} failed solves, model vs plant one sample on "
          f"{info.get('prediction_error_max', float('nan')):.1e}): summed IAE ÷ PI "
          f"{o / pi:.3f}")
    print(f"robust MPC ÷ PI {mpc / pi:.3f}; MPC ÷ oracle {mpc / o:.3f}; the MPC takes "
          f"{(pi - mpc) / (pi - o):.0%} of the room below the PI")
    return 0


if __name__ == "__main__":
    sys.exit(main())
