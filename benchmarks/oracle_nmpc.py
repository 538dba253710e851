"""Oracle NMPC of the four-tank plant: the reference of ``bench_tracking.py``, not a controller
users run (it is kept out of the shipped packages on purpose).

It knows what no real controller knows: the plant's equations and parameters exactly (the
four-tank model of ``fmus/fourtank/model.c``, its parameters read from the FMU's
modelDescription) and the plant's true state, the four levels ``h1 … h4``, which the FMU
exposes as outputs (the master wires them to the controller inputs of the same name; with no
sensor noise in the scenario what the controller reads is the true state). It has no noise,
no observer, no constraint tightening and no terminal ingredient; it does not know future
set-points. Each sample it solves::

    min_{X, U}  Σ_{i=1}^{N} ‖y_i − r‖²_Q + Σ_{i=0}^{N−1} ‖u_i − ū(r)‖²_R
    s.t.        X_0 = h_k,  X_{i+1} = F(X_i, u_i),  u_i in the input box

in the control problem's normalised units (outputs by the output box, inputs by the input box,
:meth:`controllers.problem.ControlProblem.normalization`), ``Q = I``, ``R = 0.01 I``; ``ū(r)``
is the plant's exact steady-state input of the set-point (clipped into the box); ``F`` is RK4
on the four-tank ODE over one sample ``Ts`` (``substeps`` steps). Multiple shooting, IPOPT
(exact Hessian, MUMPS), warm-started from the previous solution shifted by one sample. Every
answer is checked independently of IPOPT's status (shooting defects, input box); a failed
solve is retried from a cold start, and if that fails too the previous plan, shifted, is
applied (counted in ``failures``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from controllers.problem import ControlProblem
from cosim.core.component import Component, Signal

__all__ = ["FourTankParameters", "OracleNMPC"]

#: The plant's states, in the order of its ODE (tanks 1 … 4).
STATES = ("h1", "h2", "h3", "h4")
#: Smoothing width [m] of ``max(h, 0)`` under Torricelli's square root (the plant's
#: empty-tank rule); at the scenario's levels (> 0.1 m) the smoothed model differs from the
#: plant's by < 1e-7 m/s.
SMOOTH_H = 1e-4
#: Largest shooting defect [m] and input-box excess [normalised] an answer may have.
CHECK_TOL = 1e-7
#: IPOPT options: quiet, tight, bounded iteration count.
IPOPT_OPTIONS: dict[str, Any] = {"print_level": 0, "tol": 1e-9, "max_iter": 300,
                                 "sb": "yes"}


@dataclass(frozen=True)
class FourTankParameters:
    """The four-tank plant's parameters (``fmus/fourtank/model.c``).

    Attributes
    ----------
    S : float
        Cross-section of each tank [m²].
    a : tuple of float
        Outlet areas of tanks 1 … 4 [m²].
    gamma_a, gamma_b : float
        Fractions of ``qa`` going to tank 1 and of ``qb`` going to tank 2.
    g : float
        Gravitational acceleration [m/s²].
    """

    S: float
    a: tuple[float, float, float, float]
    gamma_a: float
    gamma_b: float
    g: float

    @classmethod
    def from_fmu(cls, fmu: str | Path) -> FourTankParameters:
        """The start values of the parameters in the FMU's modelDescription."""
        from cosim.core.fmu_archive import read_model_description

        md = read_model_description(fmu)
        start = {v.name: float(v.start) for v in md.modelVariables if v.start is not None}
        return cls(S=start["S"], a=(start["a1"], start["a2"], start["a3"], start["a4"]),
                   gamma_a=start["gamma_a"], gamma_b=start["gamma_b"], g=start["g"])

    def rhs(self, h: Any, qa: Any, qb: Any) -> Any:
        """``dh/dt`` of the four-tank ODE (casadi expressions); ``max(h, 0)`` smoothed."""
        level = 0.5 * (h + ca.sqrt(h * h + SMOOTH_H**2))
        out = [self.a[i] * ca.sqrt(2.0 * self.g * level[i]) for i in range(4)]
        ga, gb = self.gamma_a, self.gamma_b
        inflow = [out[2] + ga * qa, out[3] + gb * qb, (1.0 - gb) * qb, (1.0 - ga) * qa]
        return ca.vertcat(*[(inflow[i] - out[i]) / self.S for i in range(4)])

    def steady_inputs(self, h1: float, h2: float) -> np.ndarray:
        """The inputs ``(qa, qb)`` [m³/s] that hold ``h1, h2`` [m] at rest (may be outside the
        input box): ``a1 √(2 g h1) = γa qa + (1 − γb) qb``, ``a2 √(2 g h2) = (1 − γa) qa +
        γb qb``."""
        ga, gb = self.gamma_a, self.gamma_b
        gains = np.array([[ga, 1.0 - gb], [1.0 - ga, gb]])
        outflow = np.array([self.a[0] * math.sqrt(2.0 * self.g * max(h1, 0.0)),
                            self.a[1] * math.sqrt(2.0 * self.g * max(h2, 0.0))])
        return np.linalg.solve(gains, outflow)


def rk4_map(params: FourTankParameters, Ts: float, substeps: int) -> ca.Function:
    """``F(h, u) → h⁺``: RK4 over ``Ts`` in ``substeps`` steps, ``u = (qa, qb)`` held [m³/s]."""
    h = ca.SX.sym("h", 4)
    u = ca.SX.sym("u", 2)
    dt = Ts / substeps
    x = h
    for _ in range(substeps):
        k1 = params.rhs(x, u[0], u[1])
        k2 = params.rhs(x + 0.5 * dt * k1, u[0], u[1])
        k3 = params.rhs(x + 0.5 * dt * k2, u[0], u[1])
        k4 = params.rhs(x + dt * k3, u[0], u[1])
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [h, u], [x])


@dataclass
class Plan:
    """A solved horizon: states ``X`` ((N+1)×4, m) and normalised inputs ``U`` (N×2)."""

    X: np.ndarray
    U: np.ndarray

    def shifted(self, F: ca.Function, u_phys: Any) -> Plan:
        """The plan one sample later: first stage dropped, its last input repeated."""
        U = np.vstack([self.U[1:], self.U[-1:]])
        x_last = np.asarray(F(self.X[-1], u_phys(self.U[-1]))).ravel()
        return Plan(np.vstack([self.X[1:], x_last]), U)


class OracleTracker:
    """The FHOCP of the module docstring, built once and solved per sample.

    Parameters
    ----------
    params : FourTankParameters
    problem : ControlProblem
        Signals, boxes, normalisation and ``Ts`` (inputs ``qa, qb``; outputs ``h1, h2``).
    horizon : int
        ``N`` [samples].
    substeps : int
        RK4 steps per sample.
    r_weight : float
        ``R = r_weight · I`` (``Q = I``).
    """

    def __init__(self, params: FourTankParameters, problem: ControlProblem, horizon: int,
                 substeps: int, r_weight: float) -> None:
        self.params, self.N = params, horizon
        norm = problem.normalization()
        self.u_off, self.u_scale = norm["u_offset"], norm["u_scale"]
        self.y_off, self.y_scale = norm["y_offset"], norm["y_scale"]
        self.out_index = [STATES.index(name) for name in problem.output_names]
        self.F = rk4_map(params, problem.Ts, substeps)
        self.F_N = self.F.map(horizon)
        self.solver = self._build(r_weight)
        self.nx = 4 * (horizon + 1)
        lbx = np.full(self.nx + 2 * horizon, -np.inf)
        ubx = np.full_like(lbx, np.inf)
        lbx[self.nx:], ubx[self.nx:] = -1.0, 1.0
        self.lbx, self.ubx = lbx, ubx

    def u_phys(self, u_norm: Any) -> np.ndarray:
        """Normalised inputs → m³/s."""
        return self.u_off + self.u_scale * np.asarray(u_norm, dtype=float)

    def _build(self, r_weight: float) -> Any:
        """The multiple-shooting NLP and its IPOPT solver."""
        N = self.N
        X = ca.SX.sym("X", 4, N + 1)
        U = ca.SX.sym("U", 2, N)
        p = ca.SX.sym("p", 8)  # h_k (4), r normalised (2), ū normalised (2)
        u_phys = ca.diag(ca.DM(self.u_scale)) @ U + ca.repmat(ca.DM(self.u_off), 1, N)
        X_next = self.F_N(X[:, :N], u_phys)
        g = ca.vertcat(ca.vec(X[:, 0] - p[:4]), ca.vec(X[:, 1:] - X_next))
        y = ca.diag(ca.DM(1.0 / self.y_scale)) @ (X[self.out_index, 1:]
                                           - ca.repmat(ca.DM(self.y_off), 1, N))
        cost = (ca.sumsqr(y - ca.repmat(p[4:6], 1, N))
                + r_weight * ca.sumsqr(U - ca.repmat(p[6:8], 1, N)))
        nlp = {"x": ca.vertcat(ca.vec(X), ca.vec(U)), "p": p, "f": cost, "g": g}
        return ca.nlpsol("oracle", "ipopt", nlp, {"ipopt": IPOPT_OPTIONS, "print_time": False})

    def targets(self, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised set-point ``r`` and steady-state input ``ū`` (clipped into the box)."""
        u_bar = self.params.steady_inputs(*ref)
        u_bar_n = np.clip((u_bar - self.u_off) / self.u_scale, -1.0, 1.0)
        return (ref - self.y_off) / self.y_scale, u_bar_n

    def cold_plan(self, h: np.ndarray, u_bar_n: np.ndarray) -> Plan:
        """``ū`` held over the horizon and its rollout from ``h``."""
        U = np.tile(u_bar_n, (self.N, 1))
        X = [h]
        for u in U:
            X.append(np.asarray(self.F(X[-1], self.u_phys(u))).ravel())
        return Plan(np.array(X), U)

    def solve(self, h: np.ndarray, r_n: np.ndarray, u_bar_n: np.ndarray, start: Plan
              ) -> tuple[Plan, bool, int]:
        """Solve from ``start``; the plan, whether it passed every check, IPOPT iterations."""
        x0 = np.concatenate([start.X.ravel(), start.U.ravel()])
        sol = self.solver(x0=x0, p=np.concatenate([h, r_n, u_bar_n]), lbx=self.lbx,
                          ubx=self.ubx, lbg=0.0, ubg=0.0)
        stats = self.solver.stats()
        w = np.asarray(sol["x"]).ravel()
        plan = Plan(w[:self.nx].reshape(self.N + 1, 4), w[self.nx:].reshape(self.N, 2))
        ok = bool(stats["success"]) and self.check(plan, h)
        return plan, ok, int(stats["iter_count"])

    def check(self, plan: Plan, h: np.ndarray) -> bool:
        """The answer, checked without IPOPT: finite, inside the box, no shooting defect."""
        if not (np.all(np.isfinite(plan.X)) and np.all(np.isfinite(plan.U))):
            return False
        if np.max(np.abs(plan.U)) > 1.0 + CHECK_TOL or np.max(np.abs(plan.X[0] - h)) > CHECK_TOL:
            return False
        x_next = np.asarray(self.F_N(plan.X[:-1].T, self.u_phys(plan.U).T)).T
        return float(np.max(np.abs(x_next - plan.X[1:]))) <= CHECK_TOL


class OracleNMPC(Component):
    """The oracle NMPC as a co-simulation controller (see the module docstring).

    Parameters
    ----------
    horizon : int
        Prediction horizon ``N`` [samples of ``Ts``].
    substeps : int
        RK4 steps per sample of the prediction model.
    r_weight : float
        ``R = r_weight · I`` on the normalised inputs (``Q = I`` on the normalised outputs).
    problem : ControlProblem or path, optional
        The control problem (default: the four-tank's ``fmus/fourtank/problem.toml``).
    fmu : path, optional
        The plant FMU whose modelDescription gives the parameters (default: the project's).

    Attributes
    ----------
    failures : int
        Samples at which neither the warm- nor the cold-started solve passed the checks.
    """

    name = "oracle"
    direct_feedthrough = True
    timing_diagnostics = frozenset({"solve_ms"})

    def __init__(self, horizon: int = 80, substeps: int = 5, r_weight: float = 0.01,
                 problem: ControlProblem | str | Path | None = None,
                 fmu: str | Path | None = None) -> None:
        from cosim.adapters.problems import load_problem
        from cosim.core.plants import plant_path

        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"oracle: horizon must be a positive integer, got {horizon!r}")
        self.problem = load_problem(problem)
        if (self.problem.input_names, self.problem.output_names) != (("qa", "qb"),
                                                                      ("h1", "h2")):
            raise ValueError(f"oracle: the four-tank problem only (inputs qa, qb; outputs "
                             f"h1, h2), got {self.problem.describe()}")
        self.params = FourTankParameters.from_fmu(plant_path(fmu))
        self.ocp = OracleTracker(self.params, self.problem, horizon, substeps, r_weight)
        self.sample_time = self.problem.Ts
        self.bounds = self.problem.bounds()
        self.inputs = tuple(Signal(s, "m") for s in STATES) + tuple(
            Signal(f"ref.{c.name}", c.unit) for c in self.problem.outputs)
        self.outputs = tuple(Signal(c.name, c.unit) for c in self.problem.inputs)
        self._values: dict[str, float] = {}
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        """Forget the previous run: no warm start, counters at zero."""
        self._plan: Plan | None = None
        self._u = self.ocp.u_phys(np.zeros(2))
        self._diag: dict[str, float] = {}
        self.failures = self.cold_starts = self.steps = 0
        self.solve_ms: list[float] = []
        self.iterations: list[int] = []
        self.pred_err: list[float] = []

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """The measured levels ``h1 … h4`` and the set-points ``ref.<output>``."""
        self._values.update(values)

    def step(self, t: float, dt: float) -> None:
        """Solve the FHOCP from the measured state; hold its first input."""
        h = np.array([self._values[s] for s in STATES])
        ref = np.array([self._values[f"ref.{o}"] for o in self.problem.output_names])
        r_n, u_bar_n = self.ocp.targets(ref)
        if self._plan is not None:  # the last plan's one-sample prediction vs the plant
            self.pred_err.append(float(np.max(np.abs(self._plan.X[1] - h))))
        t0 = time.perf_counter()
        plan, ok, iters = self._solve(h, r_n, u_bar_n)
        self.solve_ms.append((time.perf_counter() - t0) * 1e3)
        self.iterations.append(iters)
        self.steps += 1
        self._plan = plan
        self._u = self.ocp.u_phys(plan.U[0])
        self._diag = {"solve_ms": self.solve_ms[-1], "iterations": float(iters),
                      "solved": float(ok)}

    def _solve(self, h: np.ndarray, r_n: np.ndarray, u_bar_n: np.ndarray
               ) -> tuple[Plan, bool, int]:
        """Warm start from the shifted plan, else a cold start, else the shifted plan."""
        cold = self.ocp.cold_plan(h, u_bar_n)
        warm = self._plan.shifted(self.ocp.F, self.ocp.u_phys) if self._plan else None
        if warm is not None:
            warm.X[0] = h
            plan, ok, iters = self.ocp.solve(h, r_n, u_bar_n, warm)
            if ok:
                return plan, ok, iters
        self.cold_starts += warm is not None
        plan, ok, iters = self.ocp.solve(h, r_n, u_bar_n, cold)
        if ok:
            return plan, ok, iters
        self.failures += 1
        return (warm if warm is not None else cold), False, iters

    def get_outputs(self) -> dict[str, float]:
        """The inputs to apply [m³/s]."""
        return {c.name: float(v) for c, v in zip(self.problem.inputs, self._u, strict=True)}

    def diagnostics(self) -> dict[str, float]:
        """``solve_ms``, IPOPT ``iterations`` and ``solved`` (1 when the answer passed)."""
        return dict(self._diag)

    def summary(self) -> dict:
        """Solves, cold restarts, failures, solve time and the model's one-sample prediction
        error against the plant (RK4 vs the FMU's integrator)."""
        ms = np.asarray(self.solve_ms or [math.nan])
        return {"horizon": self.ocp.N, "steps": self.steps, "failures": self.failures,
                "cold_starts": self.cold_starts,
                "iterations_max": max(self.iterations, default=0),
                "solve_ms_median": float(np.median(ms)),
                "solve_ms_p99": float(np.percentile(ms, 99)),
                "prediction_error_max_m": max(self.pred_err, default=0.0)}
