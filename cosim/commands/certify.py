"""``cosim certify``: the paper's certificates for a GRU model file (``controllers.certificates``).

Prints every quantity of the theory (δISS, observer, tightening, terminal ingredients) with its
paper reference, or JSON with the paper's names; checks the hypotheses of
``th:feasibility-stability`` at the requested set-points. Exit 1 when a hypothesis fails or
the admissible set-point range is empty. ``--save`` writes the observer gains into the model
file only when every check passes, atomically (a failed write leaves the file unchanged).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from cosim.errors import EXIT_FAILED, EXIT_OK, CosimError

DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "controllers" / "models" / "fourtank_gru.json"
#: Set-points (metres) used by ``--auto-gain-scale`` when none are given: a 3×3 grid.
DEFAULT_SETPOINTS = [(a, b) for a in (0.5, 1.0, 1.5) for b in (0.5, 1.0, 1.5)]

HELP = """Compute and check the certificates of the robust GRU MPC (Schimperna & Magni) for a
model file: the gate bounds and the δISS index nu (th:stability-bonassi), rho_s and c_s
(lem:Vs), the observer gains L_z, L_r (one LP per row minimising nu_o, optionally scaled by
theta), nu_o, rho_o, c_o, kappa, L_max (lem:Vo), w_y_bar, w_bar (eq:w-bar), w_L, the
tightening a_i, b_i (eq:constraint_tightening_parameters), e_o and e_inf (eq:eo-evolution), the
terminal weight s (eq:definition_s) and, per set-point, alpha (eq:def-alpha), Assumption 1
(ass:setpoint) and the recursive-feasibility inequality (eq:condition-recursive-feasibility).
Values are in the model's normalised units; set-points are given in physical units (m)."""

EPILOG = """design levers:
  --gain-scale THETA     observer gains THETA x the LP gains (0 = open-loop observer)
  --auto-gain-scale      the largest THETA in [0, 1] for which every hypothesis holds at the
                         set-points (default set-points: {0.5, 1.0, 1.5} m squared)
  --N, --e-o0            horizon and initial observer-error bound (paper: 15, 0.02)
  --data DATA.csv        estimate w_y_bar as the largest test-set output error (normalised)

--save writes only when every check passes (otherwise the model file is left unchanged),
atomically: a failed write (full disk) leaves the previous file byte-identical.

exit codes: 0 all hypotheses hold, 1 a hypothesis fails (named), the admissible set-point
range is empty, or the model file could not be written, 2 bad input."""


def register(subparsers: Any) -> None:
    """Add the ``certify`` sub-command."""
    p = subparsers.add_parser("certify", help="compute and check the paper's certificates",
                              description=HELP, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", nargs="?", default=str(DEFAULT_MODEL),
                   help="GRU model file (default: the shipped controllers/models/"
                        "fourtank_gru.json)")
    p.add_argument("--setpoint", action="append", metavar="H1,H2", default=[],
                   help="set-point in physical units (e.g. 1.0,0.8); repeat for several")
    p.add_argument("--json", action="store_true",
                   help="print JSON with the paper's names (a list when several set-points)")
    p.add_argument("--N", type=int, default=15, help="prediction horizon N (default 15)")
    p.add_argument("--e-o0", type=float, default=0.02, dest="e_o0",
                   help="initial observer-error bound ê_o,0 (default 0.02)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gain-scale", type=float, metavar="THETA",
                   help="observer gains = THETA × LP-optimal gains")
    g.add_argument("--auto-gain-scale", action="store_true",
                   help="choose the largest THETA in [0, 1] passing every hypothesis")
    p.add_argument("--data", metavar="DATA.csv",
                   help="estimate w̄_y from this data set's test split (cosim generate-data)")
    p.add_argument("--save", action="store_true",
                   help="write L_z, L_r and w̄_y into the model file, only when every check "
                        "passes (atomic: a failed write leaves the file unchanged)")
    p.add_argument("--plot", metavar="PNG",
                   help="also draw a figure: α over the set-point plane with the admissible "
                        "and reachable regions, ê_o,k, and the tightened output bounds")
    p.set_defaults(func=run)


def _parse_setpoint(text: str, names: list[str]) -> list[float]:
    parts = text.split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        raise CosimError(f"--setpoint {text!r}: expected {len(names)} numbers "
                         f"({','.join(names)}) separated by commas") from None
    if len(values) != len(names) or not all(math.isfinite(v) for v in values):
        raise CosimError(f"--setpoint {text!r}: expected {len(names)} finite numbers "
                         f"({','.join(names)})")
    return values


def _fmt(v: Any) -> str:
    import numpy as np

    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float | int | np.floating):
        return f"{float(v):.6g}"
    arr = np.asarray(v, dtype=float)
    return "[" + ", ".join(f"{x:.4g}" for x in arr.ravel()) + "]"


def _admissible(cert: Any, model: Any) -> list[tuple[str, float | None, float | None]]:
    """Per-output admissible set-point interval ``(name, lo, hi)`` in physical units, from the
    box rows of L (``ass:setpoint`` and ``eq:condition-recursive-feasibility``);
    ``(name, None, None)`` when it is empty (or undefined: a NaN bound)."""
    import numpy as np

    rhs = cert.admissible_box()
    out: list[tuple[str, float | None, float | None]] = []
    for j, name in enumerate(model.output_names):
        lo, hi = -math.inf, math.inf
        for row, r in zip(cert.L, rhs, strict=True):
            others = np.delete(row, j)
            if row[j] == 0 or np.any(others != 0):
                continue
            bound = float(r / row[j])
            if math.isnan(bound):
                lo, hi = math.inf, -math.inf
                break
            if row[j] > 0:
                hi = min(hi, bound)
            else:
                lo = max(lo, bound)
        plo, phi = (lo * model.y_scale[j] + model.y_offset[j],
                    hi * model.y_scale[j] + model.y_offset[j])
        if model.y_scale[j] < 0:
            plo, phi = phi, plo
        out.append((name, float(plo), float(phi)) if plo <= phi else (name, None, None))
    return out


def _admissible_ranges(cert: Any, model: Any) -> list[str]:
    """Per-output admissible set-point interval (physical units), as text."""
    out = []
    for j, (name, lo, hi) in enumerate(_admissible(cert, model)):
        if lo is None or hi is None:
            out.append(f"{name}: none")
        else:
            out.append(f"{name} ∈ [{lo:.4g}, {hi:.4g}] {model.output_units[j]}".rstrip())
    return out


def _certificate(args: argparse.Namespace, model: Any, setpoints: list,
                 kwargs: dict) -> tuple[Any, str]:
    """The certificate for the options in ``args`` and a note on the observer gains."""
    import numpy as np

    from controllers import certificates as certs

    if args.auto_gain_scale:
        targets = setpoints or [model.normalize_y(np.array(s)) for s in DEFAULT_SETPOINTS]
        theta, cert = certs.choose_gain_scale(model, targets, **kwargs)
        note = ("LP gains × θ = 0 (no θ in [0, 1] passes)" if theta is None
                else f"LP gains × θ = {theta:.6g} (auto)")
    else:
        cert = certs.compute_certificate(model, gain_scale=args.gain_scale, **kwargs)
        if cert.gain_scale is not None:
            note = f"LP gains × θ = {cert.gain_scale:.6g}"
        else:
            note = "gains from the model file"
    return cert, note


def run(args: argparse.Namespace) -> int:
    """Compute the certificate, print it, check it; returns the exit code."""
    import numpy as np

    from controllers import certificates as certs
    from controllers.equilibrium import UnreachableSetpoint, equilibrium
    from controllers.model import GRUModel

    if args.N < 1:
        raise CosimError(f"--N must be >= 1, got {args.N}")
    if not (math.isfinite(args.e_o0) and args.e_o0 >= 0):
        raise CosimError(f"--e-o0 must be a non-negative number, got {args.e_o0}")
    if args.gain_scale is not None and not (math.isfinite(args.gain_scale)
                                            and args.gain_scale >= 0):
        raise CosimError(f"--gain-scale must be a non-negative number, got {args.gain_scale}")
    if args.plot:
        from cosim.outpaths import figure_file

        figure_file(args.plot, "--plot")
    model = GRUModel.load(args.model)
    names = list(model.output_names)
    setpoints_phys = [_parse_setpoint(s, names) for s in args.setpoint]
    setpoints = [model.normalize_y(np.array(s)) for s in setpoints_phys]

    w_y_bar = certs.w_y_bar_from_data(model, args.data) if args.data else None
    if w_y_bar is None and model.w_y_bar is None:
        raise CosimError(f"{args.model}: no 'w_y_bar' in the model file; estimate it with "
                         "--data DATA.csv")
    kwargs = dict(N=args.N, e_o0=args.e_o0, w_y_bar=w_y_bar)
    try:
        cert, note = _certificate(args, model, setpoints, kwargs)
    except CosimError as exc:
        if str(exc).startswith((f"{args.model}:", f"{Path(args.model)}:")):
            raise
        raise CosimError(f"{args.model}: {exc}") from None

    failures = cert.failures()
    n_design = len(failures)
    empty = [name for name, lo, _ in _admissible(cert, model) if lo is None]
    per_setpoint = []
    for sp_phys, sp in zip(setpoints_phys, setpoints, strict=True):
        label = ", ".join(f"{n}={v:g}" for n, v in zip(names, sp_phys, strict=True))
        f = cert.failures(sp)[n_design:]
        u_bar = None
        try:
            _, u = equilibrium(model, sp)
            u_bar = model.denormalize_u(u)
        except UnreachableSetpoint as exc:
            f.append(f"equilibrium: {exc}")
        per_setpoint.append((label, sp, u_bar, f))
        failures += [f"set-point {label}: {msg}" for msg in f]
    if empty:
        failures.append("admissible set-points (ass:setpoint and eq:condition-recursive-"
                        f"feasibility): none for {', '.join(empty)}")

    if args.json:
        docs = [cert.to_json(sp) for _, sp, _, _ in per_setpoint] or [cert.to_json()]
        print(json.dumps(docs[0] if len(docs) == 1 else docs, indent=1))
        for msg in failures:
            print(f"FAILED: {msg}", file=sys.stderr)
    else:
        _print_table(args.model, model, cert, note, per_setpoint)
        for msg in failures:
            print(f"FAILED: {msg}")
    if args.plot:
        path = figure(args.plot, model, cert, setpoints_phys)
        print(f"figure written to {path}", file=sys.stderr)
    if args.save and failures:
        print(f"cosim certify: not saved: {args.model} is unchanged (--save writes only when "
              "every check passes)", file=sys.stderr)
    elif args.save:
        from cosim.atomicio import output_error

        model.L_z, model.L_r, model.w_y_bar = cert.L_z, cert.L_r, cert.w_y_bar
        try:
            model.save(args.model)
        except OSError as exc:
            raise output_error(args.model, exc) from None
        print(f"saved L_z, L_r and w_y_bar to {args.model}", file=sys.stderr)
    if failures:
        print(f"cosim certify: {len(failures)} hypothesis check(s) failed", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _print_table(path: str, model: Any, cert: Any, note: str, per_setpoint: list) -> None:
    from controllers.certificates import inf_norm

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


def reachable_boundary(model: Any, points: int = 60) -> Any:
    """Physical outputs of the model equilibria along the boundary of the input box
    (``‖u‖∞ = 1``): the edge of the set of reachable set-points (``p = m = 2``)."""
    import numpy as np

    from controllers.equilibrium import state_equilibrium

    s = np.linspace(-1.0, 1.0, points)
    edges = [np.c_[s, -np.ones_like(s)], np.c_[np.ones_like(s), s],
             np.c_[s[::-1], np.ones_like(s)], np.c_[-np.ones_like(s), s[::-1]]]
    us = np.vstack(edges)
    ys, x = [], None
    for u in us:
        x = state_equilibrium(model.params, u, x)
        ys.append(model.denormalize_y(model.params["U_o"] @ x + model.params["b_o"]))
    return np.array(ys)


def figure(path: str | Path, model: Any, cert: Any, setpoints: list) -> Path:
    """Certificate figure (Agg): α(ȳ) map with the admissible set (``ass:setpoint`` and
    ``eq:condition-recursive-feasibility``) and the reachable set, the ``ê_o,k`` bound
    (``eq:eo-evolution``) and the tightened output bounds along the horizon
    (``eq:optimization-constraint``), in physical units."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    path = Path(path)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    names, units = model.output_names, model.output_units
    ax = axes[0]
    if model.p == 2:
        lo = [b[0] for b in _bounds(model)]
        hi = [b[1] for b in _bounds(model)]
        g1 = np.linspace(lo[0], hi[0], 121)
        g2 = np.linspace(lo[1], hi[1], 121)
        A = np.array([[cert.alpha(model.normalize_y(np.array([a, b]))) for a in g1]
                      for b in g2])
        top = max(float(np.nanmax(A)), 1e-9)
        im = ax.pcolormesh(g1, g2, np.clip(A, 0, None), shading="auto", cmap="viridis",
                           vmin=0, vmax=top)
        fig.colorbar(im, ax=ax, label="α (eq:def-alpha, normalised)")
        ax.contour(g1, g2, A, levels=[0.0], colors="red", linewidths=1.2)
        amin = cert.alpha_min()
        if np.isfinite(amin) and amin > 0:
            ax.contour(g1, g2, A, levels=[amin], colors="white", linewidths=1.2,
                       linestyles="--")
        rb = reachable_boundary(model)
        ax.plot(rb[:, 0], rb[:, 1], color="orange", lw=1.5)
        for sp in setpoints:
            ax.plot(sp[0], sp[1], "k+", ms=10)
        ax.set_xlabel(f"{names[0]} set-point [{units[0]}]")
        ax.set_ylabel(f"{names[1]} set-point [{units[1]}]")
        ax.set_title("α; red: α = 0 (ass:setpoint); white: α = α_min\n"
                     "(eq:condition-recursive-feasibility); orange: reachable, ‖u‖∞ ≤ 1",
                     fontsize=9)
    else:
        ax.set_axis_off()
    ax = axes[1]
    steps = int(min(20000, max(50, 6.0 / max(1e-12, 1 - cert.rho_o))))
    e = cert.e_o(steps)
    ax.plot(np.arange(steps + 1), e, label="ê_o,k")
    if np.isfinite(cert.e_inf):
        ax.axhline(cert.e_inf, color="grey", ls="--", label="ē_∞")
    ax.set_xlabel("k [samples]")
    ax.set_title("observer error bound (eq:eo-evolution)", fontsize=9)
    ax.legend()
    ax = axes[2]
    i = np.arange(cert.N + 1)
    for e_val, style in ((cert.e_o0, "-"), (cert.e_tilde, "--")):
        tb = cert.tightened_bounds(e_val)
        for j in range(cert.q):
            row = cert.L[j]
            k = int(np.flatnonzero(row)[0]) if np.count_nonzero(row) == 1 else None
            if k is None:
                continue
            bound = tb[:, j] / row[k]
            phys = bound * model.y_scale[k] + model.y_offset[k]
            ax.plot(i, phys, style, color=f"C{k}",
                    label=f"{names[k]} {'≤' if row[k] > 0 else '≥'} (ê_o = {e_val:.3g})")
    for lo_b, hi_b in _bounds(model):
        ax.axhline(lo_b, color="k", lw=0.8)
        ax.axhline(hi_b, color="k", lw=0.8)
    ax.set_xlabel("prediction step i")
    ax.set_title("tightened output bounds h − a_i ê_o − b_i − w_L (physical)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    from cosim.atomicio import replacing

    try:
        with replacing(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


def _bounds(model: Any) -> list[tuple[float, float]]:
    from controllers.problem import FOURTANK

    b = dict(zip(FOURTANK.outputs, FOURTANK.output_bounds, strict=True))
    return [b.get(n, (0.0, 1.0)) for n in model.output_names]
