"""The FHOCP ``eq:optimization`` as a plain multiple-shooting NLP: the baseline.

States and inputs are all decision variables in stage order (``x_0, u_0, x_1, …, x_N, t``)
with the dynamics ``eq:gru`` as equality constraints, casadi SX expressions, exact Hessian by
automatic differentiation, IPOPT defaults and a primal warm start: what do-mpc builds. The
benchmark (``benchmarks/bench_mpc.py``) measures the fast formulation against it, and the
tests use it as an independent, tight reference of the optimum.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from controllers import gru

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP

__all__ = ["multiple_shooting_problem"]


def multiple_shooting_problem(fhocp: FHOCP) -> tuple[dict, dict, Any, int]:
    """The casadi NLP of ``fhocp`` in multiple shooting.

    Returns
    -------
    nlp : dict
        ``{"x", "p", "f", "g"}`` for ``casadi.nlpsol``; ``p = (x̂, x̄, ū)``, then ``u_{−1}``
        when the cost has the input-rate term (its residuals ``√S (u_i − u_{i−1})``).
    options : dict
        ``nlpsol("ipopt")`` options (the FHOCP's IPOPT options).
    trajectory : casadi.Function
        ``(w, p) ↦`` the states ``x_0 … x_N`` (rows) held in ``w``.
    ng : int
        Number of constraints: ``(N+1) n`` equalities, ``N q`` output rows, ``2 n`` terminal.
    """
    p = fhocp
    n, m, N = p.n, p.m, p.N
    ops = gru.casadi_ops()
    P = {k: ca.DM(v) for k, v in p.params.items()}
    w = ca.SX.sym("w", p.nw)
    par = ca.SX.sym("p", p.npar)  # x̂, x̄, ū[, u_{−1}]
    x_hat, x_bar, u_bar = par[:n], par[n:2 * n], par[2 * n:2 * n + m]
    Qh, Rh = np.linalg.cholesky(p.Q).T, np.linalg.cholesky(p.R).T
    t = w[p.it]
    us = [w[p.iu[i].tolist()] for i in range(N)]
    xs = [w[p.ix[i].tolist()] for i in range(N + 1)]
    g: list[Any] = [xs[0] - x_hat]
    g += [gru.step(P, xs[i], us[i], ops) - xs[i + 1] for i in range(N)]
    g += [ca.mtimes(ca.DM(p.LUo), xs[i]) for i in range(N)]
    g += [xs[N] - x_bar - t, xs[N] - x_bar + t]
    res = [ca.mtimes(ca.DM(Qh), xs[i] - x_bar) for i in range(N)]
    res += [ca.mtimes(ca.DM(Rh), us[i] - u_bar) for i in range(N)]
    if p.has_du:
        Sh = ca.DM(np.sqrt(p.du_weight))
        prev = [par[2 * n + m:], *us[:-1]]
        res += [Sh * (us[i] - prev[i]) for i in range(N)]
    res.append(np.sqrt(p.s) * t)
    r = ca.vertcat(*res)
    gv = ca.vertcat(*g)
    trajectory = ca.Function("xtraj", [w, par], [ca.horzcat(*xs).T])
    nlp = {"x": w, "p": par, "f": ca.dot(r, r), "g": gv}
    return nlp, {"ipopt": dict(p.ipopt_options), "print_time": False}, trajectory, gv.shape[0]
