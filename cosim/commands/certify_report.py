"""What ``cosim certify`` prints and draws: the certificate's table, every quantity with its
label in the paper, the admissible set-points per output, each set-point's checks, the law's
verdict with what would fix each failed hypothesis, and the ``--plot`` figure
(:mod:`cosim.commands.certify` computes them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["figure", "print_table", "print_verdict"]


def _fmt(v: Any) -> str:
    import numpy as np

    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float | int | np.floating):
        return f"{float(v):.6g}"
    arr = np.asarray(v, dtype=float)
    return "[" + ", ".join(f"{x:.4g}" for x in arr.ravel()) + "]"


def _admissible_ranges(cert: Any, model: Any) -> list[str]:
    """Per-output admissible set-point interval (physical units), as text
    (:func:`controllers.certification.output_ranges.admissible_ranges`)."""
    from controllers.certification.output_ranges import admissible_ranges

    out = []
    for j, (name, lo, hi) in enumerate(admissible_ranges(cert, model)):
        if lo is None or hi is None:
            out.append(f"{name}: none")
        else:
            out.append(f"{name} ∈ [{lo:.4g}, {hi:.4g}] {model.output_units[j]}".rstrip())
    return out


def print_verdict(verdict: Any) -> None:
    """The verdict of the law certified for, and each of its findings with its fix."""
    word = ("CERTIFIED" if verdict.certified else
            "NOT CERTIFIED (usable: the robust MPC runs uncertified, with the model's measured "
            "error as its tightening)" if verdict.usable else
            "NOT USABLE (the robust MPC refuses this model, certified or not)")
    print(f"verdict ({verdict.law} law): {word}")
    for f in verdict.findings:
        print(f"  {'holds' if f.holds else 'FAILS'}: {f.hypothesis}: {f.detail}")
        if f.fix:
            print(f"    fix: {f.fix}")


def print_table(path: str, model: Any, cert: Any, note: str, per_setpoint: list) -> None:
    """The certificate of the model file ``path``: every quantity with its label in the
    paper (``note``: where the observer gains come from), the admissible set-points, and each
    set-point's ``alpha``, checks and equilibrium input."""
    from controllers.certification.bounds import inf_norm

    N = cert.N
    rows = [
        ("sigma_z", cert.sigma_z, "σ̄_z, th:stability-bonassi"),
        ("sigma_r", cert.sigma_r, "σ̄_r, th:stability-bonassi"),
        ("phi_h", cert.phi_h, "φ̄_h, th:stability-bonassi"),
        ("nu", cert.nu, "ν < 1, eq:condition-deltaiss-gru"),
        ("rho_s", cert.rho_s, "ρ_s, lem:Vs"),
        ("c_s", cert.c_s, "c_s(j) = ‖(L U_o)_(j*)‖∞, lem:Vs"),
        ("‖L_z‖∞", inf_norm(cert.L_z), f"eq:observer ({note})"),
        ("‖L_r‖∞", inf_norm(cert.L_r), f"eq:observer ({note})"),
        ("nu_o", cert.nu_o, "ν_o < 1, eq:condition-observer-convergence"),
        ("rho_o", cert.rho_o, "ρ_o, lem:Vo"),
        ("c_o", cert.c_o, "c_o, lem:Vo"),
        ("kappa", cert.kappa, "κ, lem:Vo"),
        ("L_max", cert.L_max, "L_max, eq:lyap-observer-max-gain"),
        ("w_y_bar", cert.w_y_bar, "w̄_y, max test-set output error (normalised)"),
        ("w_bar", cert.w_bar, "w̄ = κ w̄_y, eq:w-bar"),
        ("w_L", cert.w_L, "w_L(j) = Σ_k |L_jk| w̄_y, eq:optimization"),
        ("a_0", cert.a[0], "eq:constraint_tightening_parameters"),
        (f"a_N (N={N})", cert.a[N], "eq:constraint_tightening_parameters"),
        (f"b_N (N={N})", cert.b[N], "eq:constraint_tightening_parameters"),
        ("e_o0", cert.e_o0, "ê_o,0, eq:eo-evolution"),
        ("e_inf", cert.e_inf, "ē_∞ = w̄/(1 − ρ_o), eq:eo-evolution"),
        ("e_tilde", cert.e_tilde, "ẽ_o = max(ê_o,0, ē_∞), eq:def-alpha"),
        ("s", cert.s, "s = n λ_max(Q)/(1 − ρ_s²), eq:definition_s"),
        ("alpha_min", cert.alpha_min(),
         "ρ_s^N (L_max ẽ_o + w̄)/(1 − ρ_s), eq:condition-recursive-feasibility"),
    ]
    print(f"certificate of {path} (n={model.n}, m={model.m}, p={model.p}, N={N}, "
          f"normalised units)")
    width = max(len(r[0]) for r in rows) + 2
    vwidth = max(len(_fmt(r[1])) for r in rows) + 2
    for name, value, ref in rows:
        print(f"  {name:<{width}}{_fmt(value):<{vwidth}}{ref}")
    print("admissible set-points (ass:setpoint and eq:condition-recursive-feasibility): "
          + "; ".join(_admissible_ranges(cert, model)))
    for label, sp, u_bar, _ in per_setpoint:
        ubar = ("unreachable" if u_bar is None else ", ".join(
            f"{n}={v:.4g}" for n, v in zip(model.input_names, u_bar, strict=True)))
        print(f"set-point {label}: alpha = {cert.alpha(sp):.6g} (eq:def-alpha), "
              f"assumption_1 = {_fmt(cert.assumption_1(sp))}, "
              f"recursive_feasibility = {_fmt(cert.recursive_feasibility(sp))}, "
              f"ū: {ubar}")


def figure(path: str | Path, model: Any, cert: Any, setpoints: list) -> Path:
    """The ``--plot`` figure (:func:`cosim.core.plots.certificate_figure`), with the output bounds
    and, for one or two outputs, the edge of the reachable set
    (:func:`controllers.equilibrium.reachable_boundary`: physical outputs ``(k, p)``, an
    open curve for one input, a closed path for two outputs and two or more inputs)."""
    from controllers.equilibrium import reachable_boundary
    from cosim.core import plots

    reachable = reachable_boundary(model) if model.p <= 2 else None
    return plots.certificate_figure(path, model, cert, setpoints, _bounds(model), reachable)


def _bounds(model: Any) -> list[tuple[float, float]]:
    return [model.problem.channel(n).bounds for n in model.output_names]
