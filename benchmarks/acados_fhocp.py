"""The paper's FHOCP in acados: the child of ``bench_acados.py``, run with the acados venv's
Python (``make acados``: ``.venv-acados``, the ``comma-deps-acados`` wheel, which vendors its
own casadi; it cannot share the project's venv).

Reads the problems ``bench_acados.py`` captured (``problems.npz``: the GRU's weights, N, Q, R,
s, the output rows ``D U_o``, and per solve ``x̂``, ``x̄``, ``ū``, the bounds of the output rows
at ``i = 1 … N−1``, the terminal radius α and the initial inputs), builds ``eq:optimization``
as an acados OCP and solves every problem in order with each of ``--variants``
(:data:`VARIANTS`), writing the answers and times to ``--out`` (npz). The OCP, written once
for every variant::

    states      (x, t): the GRU's state and the terminal epigraph variable (t⁺ = t)
    dynamics    x⁺ = z∘x + (1 − z)∘h  (eq:gru, the project's controllers.gru.step)
    stage cost  ‖x − x̄‖²_Q + ‖u − ū‖²_R        (LINEAR_LS: exact for this cost)
    terminal    s t²,  x_N − x̄ − t ≤ 0 ≤ x_N − x̄ + t,  0 ≤ t ≤ α
    rows        D U_o x_i within the captured bounds (i = 1 … N−1; free at i = 0)
    inputs      u_i in the normalised box [−1, 1]
    x_0 = x̂ (t_0 free)

Each solve starts from the same primal guess as the project's SQP (the captured inputs, their
rollout, and ``t``), the duals from acados' previous solve.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: variant -> acados solver options (``nlp_solver_max_iter``: the kernel's cap unless given);
#: the QP: qpOASES on the fully condensed QP (dense and active-set, as the kernel's; HPIPM
#: hit its 50 interior-point iterations on these QPs)
VARIANTS = {
    "sqp-exact": {"nlp_solver_type": "SQP", "hessian_approx": "EXACT",
                  "regularize_method": "PROJECT"},
    "sqp-exact-100": {"nlp_solver_type": "SQP", "hessian_approx": "EXACT",
                      "regularize_method": "PROJECT", "nlp_solver_max_iter": 100},
    "sqp-gn": {"nlp_solver_type": "SQP", "hessian_approx": "GAUSS_NEWTON"},
    "sqp-rti": {"nlp_solver_type": "SQP_RTI", "hessian_approx": "GAUSS_NEWTON"},
}


def load_acados() -> tuple:
    """acados_template from the ``comma-deps-acados`` wheel, its libraries loaded."""
    import acados

    base = Path(acados.__file__).parent
    os.environ.setdefault("ACADOS_SOURCE_DIR", str(base / "install"))
    os.environ.setdefault("TERA_PATH", str(base / "install" / "bin" / "t_renderer"))
    os.environ.setdefault("ACADOS_PYTHON_INTERFACE_PATH", str(base / "acados_template"))
    sys.path.insert(0, str(base))
    for lib in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so"):
        ctypes.CDLL(str(base / "install" / "lib" / lib), mode=ctypes.RTLD_GLOBAL)
    from acados_template import AcadosModel, AcadosOcp, AcadosOcpSolver

    return AcadosModel, AcadosOcp, AcadosOcpSolver


def gru_step(P: dict, x, u):
    """``eq:gru`` in casadi (the project's ``controllers.gru.step``)."""
    import casadi as ca

    sig = lambda a: 1.0 / (1.0 + ca.exp(-a))  # noqa: E731
    z = sig(ca.mtimes(P["W_z"], u) + ca.mtimes(P["U_z"], x) + P["b_z"])
    r = sig(ca.mtimes(P["W_r"], u) + ca.mtimes(P["U_r"], x) + P["b_r"])
    h = ca.tanh(ca.mtimes(P["W_h"], u) + ca.mtimes(P["U_h"], r * x) + P["b_h"])
    return z * x + (1 - z) * h


def build(data: dict, variant: str, folder: Path, tol: float, max_iter: int,
          qp_solver: str = "FULL_CONDENSING_QPOASES"):
    """The acados solver of the captured problem (module docstring)."""
    import casadi as ca

    AcadosModel, AcadosOcp, AcadosOcpSolver = load_acados()
    P = {k[2:]: data[k] for k in data if k.startswith("P_")}
    N, n, m = int(data["N"]), P["W_z"].shape[0], P["W_z"].shape[1]
    Q, R, s, D = data["Q"], data["R"], float(data["s"]), data["DUo"]
    q = D.shape[0]
    model = AcadosModel()
    model.name = f"gru_fhocp_{variant.replace('-', '_')}"
    x, t, u = ca.SX.sym("x", n), ca.SX.sym("t", 1), ca.SX.sym("u", m)
    model.x, model.u = ca.vertcat(x, t), u
    model.disc_dyn_expr = ca.vertcat(gru_step(P, x, u), t)
    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    ocp.cost.cost_type, ocp.cost.cost_type_0, ocp.cost.cost_type_e = "LINEAR_LS", "LINEAR_LS", \
        "LINEAR_LS"
    ny = n + m
    Vx = np.zeros((ny, n + 1))
    Vx[:n, :n] = np.eye(n)
    Vu = np.zeros((ny, m))
    Vu[n:, :] = np.eye(m)
    W = np.zeros((ny, ny))
    W[:n, :n], W[n:, n:] = 2 * Q, 2 * R       # acados: ½ ‖·‖²_W
    for suffix in ("", "_0"):
        setattr(ocp.cost, "Vx" + suffix, Vx)
        setattr(ocp.cost, "Vu" + suffix, Vu)
        setattr(ocp.cost, "W" + suffix, W)
        setattr(ocp.cost, "yref" + suffix, np.zeros(ny))
    Vx_e = np.zeros((1, n + 1))
    Vx_e[0, n] = 1.0
    ocp.cost.Vx_e, ocp.cost.W_e, ocp.cost.yref_e = Vx_e, np.array([[2 * s]]), np.zeros(1)
    c = ocp.constraints
    c.idxbx_0 = np.arange(n)
    c.lbx_0 = c.ubx_0 = np.zeros(n)
    c.idxbu, c.lbu, c.ubu = np.arange(m), -np.ones(m), np.ones(m)
    C = np.zeros((q, n + 1))
    C[:, :n] = D
    c.C, c.D = C, np.zeros((q, m))
    c.lg, c.ug = np.full(q, -1e9), np.full(q, 1e9)
    Ce = np.zeros((2 * n, n + 1))
    Ce[:n, :n], Ce[:n, n] = np.eye(n), -1.0     # x_N − t ≤ x̄
    Ce[n:, :n], Ce[n:, n] = np.eye(n), 1.0      # x_N + t ≥ x̄
    c.C_e = Ce
    c.lg_e, c.ug_e = np.full(2 * n, -1e9), np.full(2 * n, 1e9)
    c.idxbx_e, c.lbx_e, c.ubx_e = np.array([n]), np.zeros(1), np.ones(1)
    o = ocp.solver_options
    o.nlp_solver_max_iter = max_iter
    for key, value in VARIANTS[variant].items():
        setattr(o, key, value)
    o.integrator_type = "DISCRETE"
    o.qp_solver = qp_solver
    o.tf = float(N)
    # the kernel's tolerances (tol_du 1e-6 on the Lagrangian's gradient, tol_pr 1e-8 on the
    # violations); acados' inequality residual stays at 1.2e-7 (single precision's epsilon)
    # on these problems, so its test is 1e-6
    o.nlp_solver_tol_stat, o.nlp_solver_tol_eq = tol, 1e-8
    o.nlp_solver_tol_ineq, o.nlp_solver_tol_comp = 1e-6, 1e-8
    o.print_level = 0
    ocp.code_export_directory = str(folder / f"c_{variant}")
    return AcadosOcpSolver(ocp, json_file=str(folder / f"{variant}.json"), verbose=False)


def solve_all(solver, data: dict) -> dict[str, np.ndarray]:
    """Every captured problem in order: inputs, t, times, statuses, iterations."""
    import casadi as ca

    P = {k[2:]: data[k] for k in data if k.startswith("P_")}
    N, n = int(data["N"]), P["W_z"].shape[0]
    xs, us = ca.SX.sym("x", n), ca.SX.sym("u", P["W_z"].shape[1])
    f = ca.Function("f", [xs, us], [gru_step(P, xs, us)])
    K = data["x_hat"].shape[0]
    out = {"u": np.zeros((K, N, us.shape[0])), "t": np.zeros(K), "ms": np.zeros(K),
           "acados_ms": np.zeros(K), "status": np.zeros(K, int), "iterations": np.zeros(K, int)}
    for k in range(K):
        x_hat, x_bar, u_bar = data["x_hat"][k], data["x_bar"][k], data["u_bar"][k]
        U0, t0, rows = data["u_init"][k], float(data["t_init"][k]), data["rows"][k]
        X = [x_hat]
        for u in U0:
            X.append(np.asarray(f(X[-1], u)).ravel())
        t_start = time.perf_counter()
        solver.set(0, "lbx", x_hat)
        solver.set(0, "ubx", x_hat)
        for i in range(N):
            solver.set(i, "yref", np.concatenate([x_bar, u_bar]))
            solver.set(i, "x", np.append(X[i], t0))
            solver.set(i, "u", U0[i])
            if i >= 1:
                solver.constraints_set(i, "lg", rows[i - 1, 0])
                solver.constraints_set(i, "ug", rows[i - 1, 1])
        solver.set(N, "x", np.append(X[N], t0))
        solver.constraints_set(N, "lg", np.concatenate([np.full(n, -1e9), x_bar]))
        solver.constraints_set(N, "ug", np.concatenate([x_bar, np.full(n, 1e9)]))
        solver.constraints_set(N, "ubx", np.array([data["alpha"][k]]))
        status = solver.solve()
        out["ms"][k] = (time.perf_counter() - t_start) * 1e3
        out["acados_ms"][k] = float(np.ravel(solver.get_stats("time_tot"))[0]) * 1e3
        out["status"][k] = status
        out["iterations"][k] = int(np.ravel(solver.get_stats("sqp_iter"))[0])
        out["u"][k] = np.array([solver.get(i, "u") for i in range(N)])
        out["t"][k] = float(solver.get(N, "x")[n])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("problems", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--max-iter", type=int, default=15)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args(argv)
    data = dict(np.load(args.problems))
    found = {}
    with tempfile.TemporaryDirectory(prefix="acados-fhocp-") as tmp:
        cwd = os.getcwd()
        os.chdir(tmp)        # acados_template builds in the working folder
        try:
            for variant in args.variants.split(","):
                solver = build(data, variant, Path(tmp), args.tol, args.max_iter)
                runs = [solve_all(solver, data) for _ in range(args.repeats)]
                best = runs[0]
                best["ms"] = np.min([r["ms"] for r in runs], axis=0)
                best["acados_ms"] = np.min([r["acados_ms"] for r in runs], axis=0)
                found.update({f"{variant}.{k}": v for k, v in best.items()})
        finally:
            os.chdir(cwd)
    np.savez(args.out, **found)
    return 0


if __name__ == "__main__":
    sys.exit(main())
