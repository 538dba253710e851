"""Every figure of the project, drawn with matplotlib's Agg backend (no display needed).

* :func:`run_figure`: a closed-loop run (``cosim run``'s ``figure.png``).
* :func:`compare_figure`: a result against its reference (``cosim compare --plot``).
* :func:`certificate_figure`: the certificates of a model (``cosim certify --plot``).
* :func:`identification_figure`: a trained model's free run over its record (``cosim train``).

A campaign's ``report.png`` is drawn by :func:`cosim.campaign.report.campaign_figure` with
the helpers here (:func:`signal_panel`, :func:`label`, :func:`pyplot`, :func:`save`).
Nothing here knows a plant: a figure has one panel per signal of the run's control problem,
labelled with its name and unit, for any number of inputs and outputs.

matplotlib is imported when a figure is drawn, not with this module, so that commands that
draw nothing start fast. The numbers a figure shows are computed by its caller (or by the
objects it is given); these functions only draw. Where a function writes its file atomically
(:mod:`cosim.core.atomicio`) its docstring says so; the others are given a temporary path by their
caller, which renames it into place.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core import atomicio

if TYPE_CHECKING:
    from cosim.core.compare import Comparison
    from cosim.core.master import RunResult

__all__ = ["certificate_figure", "compare_figure", "identification_figure", "label", "pyplot",
           "run_figure", "run_panels", "save", "signal_panel", "times_s"]


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (imported on the first figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: str | Path, dpi: int, atomic: bool = False) -> None:
    """Save ``fig`` to ``path`` (atomically if asked) and close it, also when saving fails."""
    plt = pyplot()
    try:
        if atomic:
            with atomicio.replacing(path) as tmp:  # a failed write keeps the previous file
                fig.savefig(tmp, dpi=dpi)
        else:
            fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------------------------
# One panel per signal (cosim run, the worst run of a campaign)
# --------------------------------------------------------------------------------------------

def label(name: str, unit: str | None) -> str:
    """``name [unit]``, or ``name`` alone when the unit is empty or unknown."""
    return f"{name} [{unit}]" if unit else name


def times_s(unit: str | None) -> str:
    """The unit of a time integral of a signal in ``unit`` (``m`` → ``m·s``)."""
    return f"{unit}·s" if unit else "s"


def signal_panel(ax: Any, t: np.ndarray, column: Any, kind: str, name: str,
                 unit: str | None, bounds: tuple[float | None, float | None] = (None, None),
                 marks: Sequence[float] = ()) -> None:
    """One signal over time in ``ax``, as in the paper's Fig. 3.

    Parameters
    ----------
    ax : matplotlib Axes
    t : array
        Times [s].
    column : callable
        ``column(name)``: the recorded column of that name, or ``None``.
    kind : str
        ``"y"``: an output (``plant.<name>``, ``sensor.<name>`` if perturbed, the set-point
        ``ref.<name>`` as a step line); ``"u"``: an input (``ctrl.<name>``, held; and
        ``plant.<name>``, what the plant got, where it differs: the operator's).
    name, unit : str
        The signal and its unit (the y label).
    bounds : (lo, hi)
        Its box: drawn, and the region outside it shaded (``None``: none).
    marks : sequence of float
        Times marked by dotted vertical lines (perturbations).
    """
    if kind == "y":
        m = column(f"sensor.{name}")
        if m is not None:
            ax.plot(t, m, color="C2", lw=0.6, alpha=0.7, label=f"{name} measured")
        y = column(f"plant.{name}")
        if y is not None:
            ax.plot(t, y, color="C0", lw=1.2, label=name)
        r = column(f"ref.{name}")
        if r is not None:
            ax.step(t, r, where="post", color="k", ls="--", lw=1.0, label=f"{name} set-point")
    else:
        u = column(f"ctrl.{name}")
        if u is not None:
            ax.step(t, u, where="post", color="C1", lw=1.0, label=name)
        got = column(f"plant.{name}")
        if got is not None and u is not None and not np.array_equal(got, u, equal_nan=True):
            ax.step(t, got, where="post", color="C0", lw=1.0, ls="-.",
                    label=f"{name} the plant got")
    lo, hi = bounds
    if lo is not None and hi is not None:
        span = (hi - lo) or 1.0
        ax.axhspan(hi, hi + 0.15 * span, color="red", alpha=0.12, lw=0)
        ax.axhspan(lo - 0.15 * span, lo, color="red", alpha=0.12, lw=0)
        ax.axhline(hi, color="red", lw=0.8)
        ax.axhline(lo, color="red", lw=0.8)
        ax.set_ylim(lo - 0.1 * span, hi + 0.1 * span)
    for tp in marks:
        ax.axvline(tp, color="0.4", ls=":", lw=0.9)
    ax.set_ylabel(label(name, unit))
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=7)


# --------------------------------------------------------------------------------------------
# cosim run
# --------------------------------------------------------------------------------------------

def run_panels(result: RunResult) -> list[tuple[str, str]]:
    """The panels of :func:`run_figure`: ``("y", output)`` for every controlled output
    (with a set-point, then the other measured ones), then ``("u", input)`` for every
    manipulated input; ``m + p`` panels for ``m`` inputs and ``p`` outputs."""
    outputs = dict.fromkeys([*result.references, *result.outputs])
    return [("y", o) for o in outputs] + [("u", u) for u in result.inputs]


def run_figure(path: str | Path, result: RunResult, title: str = "") -> Path:
    """Draw a :class:`~cosim.core.master.RunResult` into ``path`` (PNG) and return the path.

    In the style of the paper's Fig. 3, one panel per signal (:func:`run_panels`), whatever
    the plant: each controlled output (plant value, measured value if perturbed, set-point
    as a step line, the region outside its box shaded), each manipulated input (with its
    box), a dotted vertical line at each perturbation time. Names, units and boxes are the
    run's (``result.units``, ``result.bounds``: the controller's signals).
    """
    plt = pyplot()
    cols = result.columns
    data = np.asarray(result.rows, dtype=float) if result.rows else np.zeros((0, len(cols)))
    t = data[:, 0] if len(data) else np.zeros(0)
    panels = run_panels(result)
    n = max(1, len(panels))
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.2 * n + 0.6), sharex=True, squeeze=False)
    index = {c: i for i, c in enumerate(cols)}

    def column(name: str) -> np.ndarray | None:
        return data[:, index[name]] if name in index else None

    errors = ((result.controller_summary or {}).get("operator") or {}).get(
        "prediction_error") or {}
    for ax, (kind, name) in zip(axes[:, 0], panels, strict=False):
        signal_panel(ax, t, column, kind, name, result.units.get(name),
                     result.bounds.get(name, (None, None)), result.perturbation_times)
        if kind == "y":
            _prediction_note(ax, (errors.get("outputs") or {}).get(name),
                             result.units.get(name))
    axes[-1, 0].set_xlabel("time [s]")
    status = "" if result.status == "ok" else f" — {result.status}: {result.reason[:80]}"
    fig.suptitle(f"{title}{status}", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    save(fig, path, dpi=110)
    return path


def _prediction_note(ax: Any, error: dict | None, unit: str | None) -> None:
    """The controller's k-step prediction error of an output (its summary's
    ``operator.prediction_error``, :mod:`controllers.shadow`) written in its panel."""
    if not error or error.get("rms") is None or not error.get("rms_by_step"):
        return
    by_step, u = error["rms_by_step"], f" {unit}" if unit else ""
    ax.text(0.01, 0.04, f"prediction error RMS {error['rms']:.3g}{u} (1 step ahead "
            f"{by_step[0]:.3g}, {len(by_step)} ahead {by_step[-1]:.3g}; mean "
            f"{error['mean']:+.3g})", transform=ax.transAxes, fontsize=7, color="0.25")


# --------------------------------------------------------------------------------------------
# cosim compare
# --------------------------------------------------------------------------------------------

def compare_figure(c: Comparison, path: str | Path, max_signals: int = 16) -> Path:
    """Draw a :class:`~cosim.core.compare.Comparison`: per signal the reference, the result, the
    band and the failing points.

    Failing signals are drawn first; at most ``max_signals`` panels. The file is replaced
    atomically (:mod:`cosim.core.atomicio`): a failed write raises
    :class:`~cosim.core.errors.OutputError` and leaves the previous file unchanged.
    """
    plt = pyplot()
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
    save(fig, path, dpi=100, atomic=True)
    return path


# --------------------------------------------------------------------------------------------
# cosim certify
# --------------------------------------------------------------------------------------------

def certificate_figure(path: str | Path, model: Any, cert: Any, setpoints: list,
                       bounds: Sequence[tuple[float, float]],
                       reachable: np.ndarray | None = None) -> Path:
    """Certificate figure, for any number of outputs ``p``, in the problem's units: the
    admissible set-points (``ass:setpoint`` and ``eq:condition-recursive-feasibility``), the
    ``ê_o,k`` bound (``eq:eo-evolution``) and, one panel per output, its tightened bounds
    along the horizon (``eq:optimization-constraint``).

    The admissible set is the α(ȳ) map over the output box for ``p = 2`` (with the edge of
    the reachable set when given), α along the box for ``p = 1`` (with the reachable
    interval), and for ``p ≥ 3`` α along each output's box with the others at the middle of
    theirs.

    Parameters
    ----------
    path : str or Path
        The PNG, replaced atomically.
    model, cert
        The :class:`~controllers.model.GRUModel` (names, units, normalisation) and its
        certificate.
    setpoints : list
        Set-points to mark, physical units, one value per output.
    bounds : sequence of (lo, hi)
        The output boxes, physical units, one per model output.
    reachable : (k, p) array, optional
        Outputs along the edge of the reachable set, physical units: drawn when ``p = 2``;
        when ``p = 1`` its extremes bound the reachable interval (shaded).
    """
    plt = pyplot()
    path = Path(path)
    p = len(bounds)
    fig = plt.figure(figsize=(15, max(4.6, 1.6 * p + 1.0)))
    grid = fig.add_gridspec(1, 3)
    _admissible_panel(fig, fig.add_subplot(grid[0, 0]), model, cert, setpoints, bounds,
                      reachable)
    ax = fig.add_subplot(grid[0, 1])
    steps = int(min(20000, max(50, 6.0 / max(1e-12, 1 - cert.rho_o))))
    e = cert.e_o(steps)
    ax.plot(np.arange(steps + 1), e, label="ê_o,k")
    if np.isfinite(cert.e_inf):
        ax.axhline(cert.e_inf, color="grey", ls="--", label="ē_∞")
    ax.set_xlabel("k [samples]")
    ax.set_ylabel("‖x − x̂‖∞ bound (normalised)")
    ax.set_title("observer error bound (eq:eo-evolution)", fontsize=9)
    ax.legend()
    names, units = list(model.output_names), list(model.output_units)
    axes = grid[0, 2].subgridspec(p, 1, hspace=0.15).subplots(sharex=True, squeeze=False)
    i = np.arange(cert.N + 1)
    for e_val, style, what in ((cert.e_o0, "-", "ê_o,0"), (cert.e_tilde, "--", "ẽ_o")):
        tb = cert.tightened_bounds(e_val)
        for j in range(cert.q):
            row = cert.L[j]
            k = int(np.flatnonzero(row)[0]) if np.count_nonzero(row) == 1 else None
            if k is None or k >= p:
                continue
            phys = tb[:, j] / row[k] * model.y_scale[k] + model.y_offset[k]
            axes[k, 0].plot(i, phys, style, color=f"C{k}",
                            label=f"ê_o = {what} = {e_val:.3g}" if row[k] > 0 else None)
    for k, (lo_b, hi_b) in enumerate(bounds):
        ax = axes[k, 0]
        ax.axhline(lo_b, color="k", lw=0.8)
        ax.axhline(hi_b, color="k", lw=0.8)
        ax.set_ylabel(label(names[k], units[k]), fontsize=8)
        ax.tick_params(labelsize=7)
    if axes[0, 0].get_legend_handles_labels()[0]:
        axes[0, 0].legend(fontsize=7, loc="best")
    axes[0, 0].set_title("tightened output bounds h − a_i ê_o − b_i − w_L", fontsize=9)
    axes[-1, 0].set_xlabel("prediction step i")
    fig.tight_layout()
    save(fig, path, dpi=110, atomic=True)
    return path


def _admissible_panel(fig: Any, ax: Any, model: Any, cert: Any, setpoints: list,
                      bounds: Sequence[tuple[float, float]],
                      reachable: np.ndarray | None) -> None:
    """The admissible set-points of :func:`certificate_figure` (see there): a map of ``α``
    over the set-points of two outputs, else its profiles along each output's box."""
    lo = np.array([b[0] for b in bounds], dtype=float)
    hi = np.array([b[1] for b in bounds], dtype=float)
    amin = cert.alpha_min()
    amin = amin if np.isfinite(amin) and amin > 0 else None

    def alpha(y: np.ndarray) -> float:
        return float(cert.alpha(model.normalize_y(y)))

    if len(bounds) == 2:
        _alpha_map(fig, ax, model, alpha, lo, hi, amin, setpoints, reachable)
    else:
        _alpha_profiles(ax, model, alpha, lo, hi, amin, setpoints, reachable)


def _alpha_map(fig: Any, ax: Any, model: Any, alpha: Any, lo: np.ndarray, hi: np.ndarray,
               amin: float | None, setpoints: list, reachable: np.ndarray | None) -> None:
    """``α`` (eq:def-alpha) over the set-points of two outputs, with its contours ``α = 0``
    (ass:setpoint) and ``α = α_min`` (eq:condition-recursive-feasibility), the edge of the
    reachable set and the set-points checked."""
    names, units = list(model.output_names), list(model.output_units)
    g1, g2 = np.linspace(lo[0], hi[0], 121), np.linspace(lo[1], hi[1], 121)
    A = np.array([[alpha(np.array([a, b])) for a in g1] for b in g2])
    top = max(float(np.nanmax(A)), 1e-9)
    im = ax.pcolormesh(g1, g2, np.clip(A, 0, None), shading="auto", cmap="viridis",
                       vmin=0, vmax=top)
    fig.colorbar(im, ax=ax, label="α (eq:def-alpha, normalised)")
    ax.contour(g1, g2, A, levels=[0.0], colors="red", linewidths=1.2)
    if amin is not None:
        ax.contour(g1, g2, A, levels=[amin], colors="white", linewidths=1.2,
                   linestyles="--")
    if reachable is not None:
        ax.plot(reachable[:, 0], reachable[:, 1], color="orange", lw=1.5)
    for sp in setpoints:
        ax.plot(sp[0], sp[1], "k+", ms=10)
    ax.set_xlabel(label(f"{names[0]} set-point", units[0]))
    ax.set_ylabel(label(f"{names[1]} set-point", units[1]))
    ax.set_title("α; red: α = 0 (ass:setpoint); white: α = α_min\n"
                 "(eq:condition-recursive-feasibility)"
                 + ("; orange: reachable, ‖u‖∞ ≤ 1" if reachable is not None else ""),
                 fontsize=9)


def _alpha_profiles(ax: Any, model: Any, alpha: Any, lo: np.ndarray, hi: np.ndarray,
                    amin: float | None, setpoints: list, reachable: np.ndarray | None) -> None:
    """``α`` (eq:def-alpha) along each output's box, the others at its middle (one output:
    over its set-points, with the reachable ones and the set-points checked)."""
    names, units = list(model.output_names), list(model.output_units)
    p = len(lo)
    s = np.linspace(0.0, 1.0, 121)
    middle = 0.5 * (lo + hi)
    for k in range(p):
        ys = [middle.copy() for _ in s]
        for y, f in zip(ys, s, strict=True):
            y[k] = lo[k] + f * (hi[k] - lo[k])
        a = [alpha(y) for y in ys]
        x = lo[k] + s * (hi[k] - lo[k]) if p == 1 else s
        ax.plot(x, a, color=f"C{k}",
                label=f"{names[k]} ∈ [{lo[k]:g}, {hi[k]:g}]" + (f" {units[k]}" if units[k]
                                                                 else ""))
    ax.axhline(0.0, color="red", lw=1.0)
    if amin is not None:
        ax.axhline(amin, color="grey", ls="--", lw=1.0)
    if p == 1:
        if reachable is not None and len(reachable):
            r = np.asarray(reachable, dtype=float)[:, 0]
            ax.axvspan(float(r.min()), float(r.max()), color="orange", alpha=0.15, lw=0,
                       label="reachable, ‖u‖∞ ≤ 1")
        for sp in setpoints:
            ax.axvline(float(np.ravel(sp)[0]), color="k", ls=":", lw=0.9)
        ax.set_xlabel(label(f"{names[0]} set-point", units[0]))
    else:
        ax.set_xlabel("set-point: position in its box (0 = min, 1 = max); the others at "
                      "the middle", fontsize=8)
    ax.set_ylabel("α (eq:def-alpha, normalised)")
    ax.set_title("admissible where α > 0 (red: α = 0, ass:setpoint) and α ≥ α_min\n"
                 "(grey, eq:condition-recursive-feasibility)", fontsize=9)
    ax.legend(fontsize=7)


# --------------------------------------------------------------------------------------------
# cosim train
# --------------------------------------------------------------------------------------------

def identification_figure(path: str | Path, y: np.ndarray, xi: np.ndarray,
                          baseline: np.ndarray | None, split: np.ndarray,
                          experiment: np.ndarray, names: list[str], units: list[str],
                          Ts: float, measured: str, title: str) -> None:
    """A trained model against the record (one panel per output) into ``path`` (PNG).

    Parameters
    ----------
    y, xi : (T, p) arrays
        Measured outputs and the model's free run, physical units.
    baseline : (T, p) array or None
        The linear baseline's free run.
    split, experiment : (T,) arrays
        Each row's split (shaded: validation blue, test orange) and experiment (a vertical
        line where one ends); the experiments are drawn one after the other.
    Ts : float
        Sample time [s]: the axis is hours of record.
    measured : str
        The legend of ``y``: ``"measured (log)"`` or ``"measured (plant FMU)"``.
    """
    plt = pyplot()
    t = np.arange(len(y)) * Ts / 3600.0
    shade = {"val": ("tab:blue", "validation"), "test": ("tab:orange", "test")}
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 2.7 * len(names)), sharex=True,
                             squeeze=False)
    cuts = np.flatnonzero(np.asarray(experiment)[1:] != np.asarray(experiment)[:-1]) + 1
    for j, ax in enumerate(axes[:, 0]):
        for name, (color, text) in shade.items():
            rows = np.flatnonzero(np.asarray(split) == name)
            runs = np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1) if rows.size else []
            for k, run in enumerate(runs):
                ax.axvspan(t[run[0]], t[run[-1]] + Ts / 3600.0, color=color, alpha=0.08,
                           lw=0, label=f"{text} rows" if j == 0 and k == 0 else None)
        for c in cuts:
            ax.axvline(t[c], color="0.4", lw=0.8, ls=":")
        ax.plot(t, y[:, j], color="black", lw=0.9, label=measured)
        ax.plot(t, xi[:, j], color="tab:red", lw=1.0, ls="--", label="GRU, free run")
        if baseline is not None:
            ax.plot(t, baseline[:, j], color="tab:green", lw=0.9, ls=":",
                    label="ARX baseline, free run")
        ax.set_ylabel(label(names[j], units[j]))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel("hours of record (experiments one after the other, dotted lines "
                           "between them)" if cuts.size else "hours of record")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save(fig, path, dpi=110)
