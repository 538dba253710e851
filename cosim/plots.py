"""Every figure of the project, drawn with matplotlib's Agg backend (no display needed).

* :func:`run_figure`: a closed-loop run (``cosim run``'s ``figure.png``).
* :func:`compare_figure`: a result against its reference (``cosim compare --plot``).
* :func:`certificate_figure`: the certificates of a model (``cosim certify --plot``).
* :func:`prediction_figure`: a trained model's test-split prediction (``cosim train``).
* :func:`campaign_figure`: a campaign's violations and KPIs (``report.png``).

matplotlib is imported when a figure is drawn, not with this module, so that commands that
draw nothing start fast. The numbers a figure shows are computed by its caller (or by the
objects it is given); these functions only draw. Where a function writes its file atomically
(:mod:`cosim.atomicio`) its docstring says so; the others are given a temporary path by their
caller, which renames it into place.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim import atomicio

if TYPE_CHECKING:
    from cosim.compare import Comparison
    from cosim.master import RunResult

__all__ = [
    "campaign_figure",
    "certificate_figure",
    "compare_figure",
    "prediction_figure",
    "run_figure",
]


def _pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | Path, dpi: int, atomic: bool = False) -> None:
    """Save ``fig`` to ``path`` (atomically if asked) and close it, also when saving fails."""
    plt = _pyplot()
    try:
        if atomic:
            with atomicio.replacing(path) as tmp:  # a failed write keeps the previous file
                fig.savefig(tmp, dpi=dpi)
        else:
            fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------------------------
# cosim run
# --------------------------------------------------------------------------------------------

def run_figure(path: str | Path, result: RunResult, title: str = "") -> Path:
    """Draw a :class:`~cosim.master.RunResult` into ``path`` (PNG) and return the path.

    In the style of the paper's Fig. 3: one panel per controlled output (plant value,
    measured value if perturbed, set-point as a step line, the region outside the output
    constraints shaded), one panel per manipulated input (with its bounds), and a dotted
    vertical line at each perturbation time.
    """
    plt = _pyplot()
    cols = result.columns
    data = np.asarray(result.rows, dtype=float) if result.rows else np.zeros((0, len(cols)))
    t = data[:, 0] if len(data) else np.zeros(0)
    panels = [("y", o) for o in result.outputs] + [("u", u) for u in result.inputs]
    n = max(1, len(panels))
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.2 * n + 0.6), sharex=True, squeeze=False)
    for ax, (kind, name) in zip(axes[:, 0], panels, strict=False):
        def col(c: str) -> np.ndarray | None:
            return data[:, cols.index(c)] if c in cols else None

        if kind == "y":
            m = col(f"sensor.{name}")
            if m is not None:
                ax.plot(t, m, color="C2", lw=0.6, alpha=0.7, label=f"{name} measured")
            y = col(f"plant.{name}")
            if y is not None:
                ax.plot(t, y, color="C0", lw=1.2, label=name)
            r = col(f"ref.{name}")
            if r is not None:
                ax.step(t, r, where="post", color="k", ls="--", lw=1.0, label=f"{name} set-point")
        else:
            u = col(f"ctrl.{name}")
            if u is not None:
                ax.step(t, u, where="post", color="C1", lw=1.0, label=name)
        lo, hi = result.bounds.get(name, (None, None))
        if lo is not None and hi is not None:
            span = hi - lo
            ax.axhspan(hi, hi + 0.15 * span, color="red", alpha=0.12, lw=0)
            ax.axhspan(lo - 0.15 * span, lo, color="red", alpha=0.12, lw=0)
            ax.axhline(hi, color="red", lw=0.8)
            ax.axhline(lo, color="red", lw=0.8)
            ax.set_ylim(lo - 0.1 * span, hi + 0.1 * span)
        for tp in result.perturbation_times:
            ax.axvline(tp, color="0.4", ls=":", lw=0.9)
        unit = result.units.get(name)
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    status = "" if result.status == "ok" else f" — {result.status}: {result.reason[:80]}"
    fig.suptitle(f"{title}{status}", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    _save(fig, path, dpi=110)
    return path


# --------------------------------------------------------------------------------------------
# cosim compare
# --------------------------------------------------------------------------------------------

def compare_figure(c: Comparison, path: str | Path, max_signals: int = 16) -> Path:
    """Draw a :class:`~cosim.compare.Comparison`: per signal the reference, the result, the
    band and the failing points.

    Failing signals are drawn first; at most ``max_signals`` panels. The file is replaced
    atomically (:mod:`cosim.atomicio`): a failed write raises
    :class:`~cosim.errors.OutputError` and leaves the previous file unchanged.
    """
    plt = _pyplot()
    path = Path(path)
    ordered = c.failed + [s for s in c.signals if s.passed]
    shown = ordered[:max_signals]
    fig, axes = plt.subplots(len(shown), 1, sharex=True, squeeze=False,
                             figsize=(9, 1.2 + 2.0 * len(shown)))
    for ax, s in zip(axes[:, 0], shown, strict=True):
        ax.fill_between(s.time, s.lower, s.upper, color="tab:blue", alpha=0.2, lw=0,
                        label="tolerance band")
        ax.plot(s.time, s.reference, color="tab:blue", lw=1.0, label="reference")
        ax.plot(s.time, s.result, color="tab:orange", lw=1.0, ls="--", label="result")
        if not s.passed:
            bad = s.outside & ~np.isnan(s.result)
            ax.plot(s.time[bad], s.result[bad], "x", color="tab:red", ms=5,
                    label=f"outside ({s.n_outside})")
        ax.set_ylabel(s.name)
        ax.set_title(f"{s.name}: {'PASS' if s.passed else 'FAIL'}", fontsize=9, loc="left",
                     color="black" if s.passed else "tab:red")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel("time [s]")
    more = len(ordered) - len(shown)
    title = f"{c.result_path.name} vs {c.reference_path.name}: " \
            f"{'PASS' if c.passed else 'FAIL'}" + (f" ({more} more signals not shown)"
                                                   if more else "")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path, dpi=100, atomic=True)
    return path


# --------------------------------------------------------------------------------------------
# cosim certify
# --------------------------------------------------------------------------------------------

def certificate_figure(path: str | Path, model: Any, cert: Any, setpoints: list,
                       bounds: Sequence[tuple[float, float]],
                       reachable: np.ndarray | None = None) -> Path:
    """Certificate figure: the α(ȳ) map with the admissible set (``ass:setpoint`` and
    ``eq:condition-recursive-feasibility``) and the reachable set, the ``ê_o,k`` bound
    (``eq:eo-evolution``) and the tightened output bounds along the horizon
    (``eq:optimization-constraint``), in physical units.

    Parameters
    ----------
    path : str or Path
        The PNG, replaced atomically.
    model, cert
        The :class:`~controllers.model.GRUModel` and its certificate.
    setpoints : list
        Set-points to mark, physical units.
    bounds : sequence of (lo, hi)
        The output constraints, physical units, one per model output.
    reachable : (k, 2) array, optional
        Outputs along the edge of the reachable set (drawn when the model has two outputs).
    """
    plt = _pyplot()
    path = Path(path)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    names, units = model.output_names, model.output_units
    ax = axes[0]
    if model.p == 2:
        lo = [b[0] for b in bounds]
        hi = [b[1] for b in bounds]
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
        if reachable is not None:
            ax.plot(reachable[:, 0], reachable[:, 1], color="orange", lw=1.5)
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
    for lo_b, hi_b in bounds:
        ax.axhline(lo_b, color="k", lw=0.8)
        ax.axhline(hi_b, color="k", lw=0.8)
    ax.set_xlabel("prediction step i")
    ax.set_title("tightened output bounds h − a_i ê_o − b_i − w_L (physical)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path, dpi=110, atomic=True)
    return path


# --------------------------------------------------------------------------------------------
# cosim train
# --------------------------------------------------------------------------------------------

def prediction_figure(time: np.ndarray, y: np.ndarray, xi: np.ndarray, names: list[str],
                      units: list[str], fits: list[float], path: str | Path,
                      title: str) -> None:
    """Measured vs predicted outputs (one panel per output) into ``path`` (PNG).

    Parameters
    ----------
    time : (T,) array
        Sample times [s]; the axis shows hours from the first.
    y, xi : (T, p) arrays
        Measured and open-loop predicted outputs, physical units.
    names, units : list of str
        Per output.
    fits : list of float
        FIT per output [%] (:func:`controllers.metrics.fit`), shown in each panel's title.
    path : str or Path
    title : str
    """
    plt = _pyplot()
    t = (time - time[0]) / 3600.0
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 2.6 * len(names)), sharex=True,
                             squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(t, y[:, j], color="tab:blue", lw=1.0, label="measured (plant FMU)")
        ax.plot(t, xi[:, j], color="tab:red", lw=1.0, ls="--", label="GRU, open loop")
        ax.set_ylabel(f"{names[j]} [{units[j]}]")
        ax.set_title(f"{names[j]}: FIT {fits[j]:.1f} %", fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time from start of test split [h]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path, dpi=120)


# --------------------------------------------------------------------------------------------
# cosim campaign
# --------------------------------------------------------------------------------------------

#: The KPI panels of :func:`campaign_figure` after the violations panel: column, title.
_CAMPAIGN_KPIS = (("iae_h1", "IAE h1 [m·s]"), ("iae_h2", "IAE h2 [m·s]"),
                 ("worst_offset", "worst static offset [m]"),
                 ("max_violation", "largest violation"), ("step_ms_p99", "step p99 [ms]"))


def campaign_figure(path: str | Path, title: str, table: Any, violating: Sequence[float],
                    upper_bounds: Sequence[float], worst: Any = None,
                    worst_results: Path | None = None) -> None:
    """A campaign's ``report.png``, replaced atomically.

    Top rows: the share of violating runs per variant with its 95 % upper bound, and a box
    plot per KPI (IAE h1 and h2, worst static offset, largest violation, step time p99) over
    the runs that finished. Bottom row: the
    outputs and inputs of the worst run.

    Parameters
    ----------
    path : str or Path
    title : str
    table : pandas.DataFrame
        One row per run and variant (``runs.parquet``).
    violating, upper_bounds : sequence of float
        Per variant (in order of first appearance in ``table``): the observed share of
        violating runs and its one-sided 95 % upper bound, in percent.
    worst : pandas row, optional
        The worst run (``run``, ``variant``, ``violation_count``, ``iae_h1``).
    worst_results : Path, optional
        Its ``results.csv``; a file that cannot be read is noted in the figure.
    """
    from cosim.csvio import read_table

    plt = _pyplot()
    variants = list(dict.fromkeys(table["variant"]))
    ok = table[table["status"] == "ok"]
    fig = plt.figure(figsize=(13, 9))
    grid = fig.add_gridspec(3, 3, hspace=0.55, wspace=0.3)
    ax = fig.add_subplot(grid[0, 0])
    x = np.arange(len(variants))
    ax.bar(x, violating, color="C3", alpha=0.7, label="observed")
    ax.scatter(x, upper_bounds, color="k", marker="_", s=400, label="95 % upper bound")
    ax.set_xticks(x, variants, rotation=15, fontsize=8)
    ax.set_title("violating runs [%]", fontsize=10)
    ax.legend(fontsize=7)
    for i, (kpi, label) in enumerate(_CAMPAIGN_KPIS, start=1):
        ax = fig.add_subplot(grid[i // 3, i % 3])
        data = [ok[ok["variant"] == v][kpi].to_numpy(dtype=float) for v in variants]
        data = [d[np.isfinite(d)] for d in data]
        if any(d.size for d in data):
            ax.boxplot([d if d.size else [np.nan] for d in data], tick_labels=variants)
            ax.tick_params(axis="x", labelrotation=15, labelsize=8)
        ax.set_title(label, fontsize=10)
    ax_y = fig.add_subplot(grid[2, :2])
    ax_u = fig.add_subplot(grid[2, 2])
    if worst is not None:
        try:
            res = read_table(worst_results)
            t = res.time
            for j, o in enumerate(("h1", "h2")):
                if f"plant.{o}" in res.names:
                    ax_y.plot(t, res.column(f"plant.{o}"), color=f"C{j}", lw=1, label=o)
                if f"ref.{o}" in res.names:
                    ax_y.step(t, res.column(f"ref.{o}"), where="post", color=f"C{j}", ls="--",
                              lw=0.8)
            for j, u in enumerate(("qa", "qb")):
                if f"ctrl.{u}" in res.names:
                    ax_u.step(t, res.column(f"ctrl.{u}"), where="post", color=f"C{j + 2}",
                              lw=0.8, label=u)
        except Exception as exc:  # the figure must not fail the campaign
            ax_y.text(0.5, 0.5, f"worst run not readable: {exc}", transform=ax_y.transAxes,
                      ha="center")
        ax_y.set_title(f"worst run: {int(worst['run'])}-{worst['variant']} "
                       f"({int(worst['violation_count'])} violations, IAE h1 "
                       f"{worst['iae_h1']:.4g} m·s)", fontsize=10)
        ax_y.set_xlabel("time [s]")
        ax_y.set_ylabel("level [m]")
        ax_y.legend(fontsize=8)
        ax_u.set_xlabel("time [s]")
        ax_u.set_ylabel("flow [m³/s]")
        ax_u.legend(fontsize=8)
    fig.suptitle(title)
    _save(fig, path, dpi=90, atomic=True)
