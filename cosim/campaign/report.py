"""A campaign's tables and figures: ``runs.parquet``, ``summary.json``, ``report.png``.

Everything is computed from the run folders (``runs/<run>-<variant>/summary.json``), so a
resumed or interrupted campaign reports exactly the runs that are on disk, and keyed by the
signals of the run's control problem (its outputs and inputs, whatever the plant).

``runs.parquet``: one row per run and variant with ``run``, ``seed``, ``variant``,
``status``, ``reason``, ``tries`` (1, or more when the run's worker process died under it and
the engine ran it again), one column per ``[draw]`` key (named exactly as in the spec), the
KPIs :data:`KPI_COLUMNS`, for a GRU-model plant under the robust MPC the theorem's checks
(:data:`THEOREM_COLUMNS`), and last the per-signal KPIs, named as their path below ``kpis``
in the run's ``summary.json`` (:func:`cosim.core.kpis.flat`): ``iae.<output>``,
``final_error.<output>``, ``worst_offset.<output>``, ``tv.<input>``,
``violations.<signal>.max`` and ``violations.<signal>.count``.

``summary.json``: ``runs``, ``ok``, ``failed``, ``retried_runs``, ``violating_runs`` and
``violation_probability_upper_95`` (one-sided Clopper-Pearson bound on the probability that
a run violates a constraint), per variant the same plus KPI quantiles (keyed by the column
names: ``quantiles["iae.h1"]``), and the failures grouped by reason.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core import atomicio, plots
from cosim.core import kpis as _kpis
from cosim.core.csvio import read_table
from cosim.core.run_result import COMPLETE

__all__ = ["KPI_COLUMNS", "THEOREM_COLUMNS", "campaign_figure", "campaign_kpi_panels",
           "clopper_pearson_upper", "kpi_row", "quantile_kpis", "run_folder_name",
           "run_signals", "signal_columns", "summarize", "theorem_checks", "worst_run",
           "write_figure", "write_summary", "write_table"]

#: KPI columns of ``runs.parquet`` that every run has, whatever its signals (besides run,
#: seed, variant, status, reason, tries, draws; the per-signal ones follow, see the module
#: docstring). ``max_violation`` and ``worst_offset`` are the largest over the signals, each
#: in its own unit.
KPI_COLUMNS = ("violation_count", "max_violation", "worst_offset", "fallbacks",
               "suboptimal_steps", "setpoint_rejected_steps", "step_ms_p99", "steps",
               "wall_time_s")
#: What the paper's theorem promises, measured per run (GRU-model plant, robust MPC).
THEOREM_COLUMNS = ("initially_feasible", "infeasible_after_first", "fallbacks_after_first",
                   "observer_checks", "observer_bound_violations", "observer_error_max_ratio",
                   "final_offset", "final_state_error", "final_output_error")
#: Quantiles of the KPIs (:func:`quantile_kpis`) in ``summary.json``.
QUANTILES = (0.05, 0.5, 0.95, 1.0)
#: Status codes of an infeasible FHOCP in the robust MPC's ``ctrl.status`` column.
INFEASIBLE_CODES = (1.0, 2.0)
#: Run folders read, at most, to find the signals' units and boxes (:func:`run_signals`).
SIGNAL_PROBES = 20


def clopper_pearson_upper(k: int, n: int, confidence: float = 0.95) -> float | None:
    """One-sided upper confidence bound of a probability after ``k`` events in ``n`` trials.

    ``P(p ≤ bound) ≥ confidence``: the ``confidence`` quantile of Beta(k + 1, n − k); 1 when
    ``k = n``; ``None`` without trials. With ``k = 0`` it is ``1 − (1 − confidence)^(1/n)``
    (the "rule of three": ≈ 3/n).
    """
    if n <= 0:
        return None
    if k >= n:
        return 1.0
    from scipy.stats import beta

    return float(beta.ppf(confidence, k + 1, n - k))


def _get(doc: dict, *path: str, default: Any = None) -> Any:
    for key in path:
        if not isinstance(doc, dict) or key not in doc:
            return default
        doc = doc[key]
    return doc


def kpi_row(doc: dict, draw_keys: Iterable[str]) -> dict[str, Any]:
    """One ``runs.parquet`` row from a run's ``summary.json`` document (see the module
    docstring for the columns)."""
    kpis = doc.get("kpis") or {}
    viol = kpis.get("violations") or {}
    cs = doc.get("controller_summary") or {}
    offsets = [abs(v) for seg in kpis.get("setpoints") or [] for v in seg["offset"].values()
               if v is not None]
    row: dict[str, Any] = {
        "run": int(_get(doc, "campaign", "run", default=-1)),
        "seed": int(_get(doc, "seed", default=-1)),
        "variant": str(_get(doc, "campaign", "variant", default="")),
        "status": doc.get("status", "failed"),
        "reason": doc.get("reason", ""),
        "tries": int(_get(doc, "campaign", "tries", default=1)),
    }
    draws = _get(doc, "campaign", "draws", default={}) or {}
    for key in draw_keys:
        row[key] = float(draws.get(key, math.nan))
    row.update({
        "violation_count": int(sum(v.get("count", 0) for v in viol.values())),
        "max_violation": float(max((v.get("max") or 0.0 for v in viol.values()), default=0.0)),
        "worst_offset": float(max(offsets, default=math.nan)),
        "fallbacks": int(cs.get("fallbacks", 0) or 0),
        "suboptimal_steps": int(cs.get("suboptimal_steps", 0) or 0),
        "setpoint_rejected_steps": int(cs.get("setpoint_rejected_steps", 0) or 0),
        "step_ms_p99": _float(cs.get("solve_ms_p99")),
        "steps": int(doc.get("steps", 0) or 0),
        "wall_time_s": _float(doc.get("wall_time_s")),
    })
    theorem = _get(doc, "campaign", "theorem")
    if theorem is not None:
        row.update({k: theorem.get(k) for k in THEOREM_COLUMNS})
    row.update(_kpis.flat(kpis))  # last: a run that failed before its first step has none
    return row


def signal_columns(table: Any, kpi: str) -> list[str]:
    """The ``<kpi>.<signal>`` columns of ``table`` (``kpi = "iae"``: ``iae.h1``, ...), in
    table order; ``violations`` columns are ``violations.<signal>.max`` / ``.count``."""
    return [c for c in table.columns if c.startswith(kpi + ".")]


def quantile_kpis(table: Any) -> list[str]:
    """The columns summarised by quantiles in ``summary.json``: ``iae.<o>`` per output,
    ``worst_offset`` and ``worst_offset.<o>``, ``max_violation``, ``tv.<u>`` per input,
    ``step_ms_p99``, ``wall_time_s``."""
    return [*signal_columns(table, "iae"), "worst_offset",
            *signal_columns(table, "worst_offset"), "max_violation",
            *signal_columns(table, "tv"), "step_ms_p99", "wall_time_s"]


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


def theorem_checks(columns: list[str], rows: np.ndarray, monitor: dict[str, Any],
                   kpis: dict) -> dict[str, Any]:
    """The theorem's promises for one run (:data:`THEOREM_COLUMNS`).

    ``monitor`` holds the observer-error checks made during the run; recursive feasibility
    is read from the ``ctrl.status`` and ``ctrl.fallback`` columns (an infeasible FHOCP or a
    fallback at a step after the first), convergence from the last set-point's offset.
    """
    def col(name: str) -> np.ndarray:
        return rows[:, columns.index(name)] if name in columns and len(rows) else np.zeros(0)

    status, fallback = col("ctrl.status"), col("ctrl.fallback")
    infeasible = np.isin(status, INFEASIBLE_CODES)
    segs = kpis.get("setpoints") or []
    final = [abs(v) for v in (segs[-1]["offset"].values() if segs else []) if v is not None]
    return {
        "initially_feasible": bool(len(status) and not infeasible[0]),
        "infeasible_after_first": int(np.count_nonzero(infeasible[1:])),
        "fallbacks_after_first": int(np.count_nonzero(fallback[1:] > 0)),
        "observer_checks": int(monitor.get("observer_checks", 0)),
        "observer_bound_violations": int(monitor.get("observer_bound_violations", 0)),
        "observer_error_max_ratio": float(monitor.get("observer_error_max_ratio", math.nan)),
        "final_offset": float(max(final, default=math.nan)),
        "final_state_error": float(monitor.get("final_state_error", math.nan)),
        "final_output_error": float(monitor.get("final_output_error", math.nan)),
    }


def _reason_group(reason: str) -> str:
    """A failure reason with times and numbers blanked, so alike failures group."""
    text = re.sub(r"t=[-+0-9.e]+", "t=…", reason)
    text = re.sub(r"\(partial results:.*\)", "", text)
    return re.sub(r"\b\d+(\.\d+)?\b", "#", text).strip()


def summarize(table: Any, name: str, planned: int) -> dict[str, Any]:
    """The campaign's ``summary.json`` document from the runs table (a DataFrame)."""

    def block(df: Any) -> dict[str, Any]:
        ok = df[df["status"].isin(COMPLETE)]
        ran = df[df["status"] != "interrupted"]
        violating = int((ran["violation_count"] > 0).sum())
        out: dict[str, Any] = {
            "runs": len(df), "ok": len(ok), "failed": int((df["status"] == "failed").sum()),
            "degraded": int((df["status"] == "degraded").sum()),
            "retried_runs": int((df["tries"] > 1).sum()) if "tries" in df else 0,
            "violating_runs": violating,
            "violation_probability_upper_95": clopper_pearson_upper(violating, len(ran)),
            "quantiles": {},
        }
        for kpi in quantile_kpis(df):
            values = ok[kpi].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            out["quantiles"][kpi] = ({f"q{int(q * 100)}": float(np.quantile(values, q))
                                      for q in QUANTILES} if values.size else None)
        if "observer_bound_violations" in df:
            out["theorem"] = {
                "initially_infeasible_runs": int((~ok["initially_feasible"].astype(bool)).sum()),
                "runs_infeasible_after_first": int((ok["infeasible_after_first"] > 0).sum()),
                "runs_with_fallback_after_first": int((ok["fallbacks_after_first"] > 0).sum()),
                "runs_observer_bound_violated": int(
                    (ok["observer_bound_violations"] > 0).sum()),
                "observer_error_max_ratio": float(ok["observer_error_max_ratio"].max())
                if len(ok) else None,
                "final_offset_max": float(ok["final_offset"].max()) if len(ok) else None,
                "final_output_error_max": float(ok["final_output_error"].max())
                if len(ok) else None,
                "final_state_error_max": float(ok["final_state_error"].max())
                if len(ok) else None,
            }
        return out

    doc: dict[str, Any] = {"campaign": name, "planned": planned}
    doc.update(block(table))
    doc["variants"] = {str(v): block(table[table["variant"] == v])
                       for v in dict.fromkeys(table["variant"])}
    failures: dict[str, dict[str, Any]] = {}
    for _, row in table[table["status"] == "failed"].iterrows():
        group = failures.setdefault(_reason_group(str(row["reason"])),
                                    {"count": 0, "runs": [], "example": str(row["reason"])})
        group["count"] += 1
        if len(group["runs"]) < 20:
            group["runs"].append(f"{int(row['run'])}-{row['variant']}")
    doc["failures_by_reason"] = dict(sorted(failures.items(), key=lambda kv: -kv[1]["count"]))
    from cosim.core.results import jsonable

    return jsonable(doc)


def write_table(table: Any, path: Path) -> None:
    """``runs.parquet`` (pyarrow), written atomically."""
    with atomicio.replacing(path) as tmp:
        table.to_parquet(tmp, index=False, engine="pyarrow")


def write_summary(doc: dict, path: Path) -> None:
    """``summary.json``, written atomically."""
    atomicio.write_text(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")


def worst_run(table: Any) -> Any:
    """The worst run that ended ok (a row of ``table``), or ``None`` when none did.

    The largest violation first; among equal ones the largest IAE summed over the outputs,
    each output's IAE relative to its median over the runs that ended ok (so that outputs
    in other units weigh alike); then the lowest run number, the variants in table order.
    """
    ok = table[table["status"].isin(COMPLETE)]
    if not len(ok):
        return None
    score = np.zeros(len(ok))
    for col in signal_columns(ok, "iae"):
        v = ok[col].to_numpy(dtype=float)
        finite = v[np.isfinite(v)]
        scale = float(np.median(np.abs(finite))) if finite.size else 0.0
        if not scale > 0:
            scale = float(np.max(np.abs(finite))) if finite.size else 0.0
        score += np.nan_to_num(v / scale if scale > 0 else v * 0.0, nan=0.0)
    ranked = ok.assign(_score=score, _order=np.arange(len(ok)))
    ranked = ranked.sort_values(["max_violation", "_score", "run", "_order"],
                                ascending=[False, False, True, True], kind="mergesort")
    return ranked.drop(columns=["_score", "_order"]).iloc[0]


def run_signals(runs_dir: Path, table: Any, first: Any = None) -> dict:
    """The ``signals`` block (outputs and inputs with unit, min, max) of the runs'
    ``summary.json``: ``first``'s run (a row of ``table``) if it has one, else the first run
    of ``table`` that has one (ok runs first; at most :data:`SIGNAL_PROBES` folders read);
    ``{}`` when none has."""
    rows = [] if first is None else [first]
    if len(table):
        ok = table["status"].isin(COMPLETE)
        for part in (table[ok], table[~ok]):
            rows += [r for _, r in part.head(SIGNAL_PROBES).iterrows()]
    for row in rows[:SIGNAL_PROBES]:
        path = runs_dir / run_folder_name(int(row["run"]), str(row["variant"])) / \
            "summary.json"
        try:
            found = json.loads(path.read_text(encoding="utf-8")).get("signals")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(found, dict) and (found.get("outputs") or found.get("inputs")):
            return found
    return {}


def write_figure(table: Any, runs_dir: Path, path: Path, title: str) -> None:
    """``report.png``: violations and KPI distributions per variant, the worst run.

    The share of violating runs per variant (with its :func:`clopper_pearson_upper` bound),
    the worst run (:func:`worst_run`) and the signals' units and boxes (:func:`run_signals`)
    are found here; the drawing is :func:`campaign_figure`.
    """
    shares, uppers = [], []
    for v in dict.fromkeys(table["variant"]):
        df = table[(table["variant"] == v) & (table["status"] != "interrupted")]
        k = int((df["violation_count"] > 0).sum())
        shares.append(100.0 * k / max(len(df), 1))
        uppers.append(100.0 * (clopper_pearson_upper(k, len(df)) or 0.0))
    worst = worst_run(table)
    worst_results = None if worst is None else (
        runs_dir / run_folder_name(int(worst["run"]), str(worst["variant"])) / "results.csv")
    campaign_figure(path, title, table, shares, uppers, worst, worst_results,
                    run_signals(runs_dir, table, worst))


def campaign_kpi_panels(outputs: Sequence[str], units: dict[str, str]) -> list[tuple[str, str]]:
    """The KPI panels of :func:`campaign_figure` after the violations panel: ``(column of
    runs.parquet, title)``: ``iae.<o>`` and ``worst_offset.<o>`` per output (in its units),
    the largest violation and the step time's p99."""
    label, times_s = plots.label, plots.times_s
    panels = [(f"iae.{o}", f"IAE {label(o, times_s(units.get(o)))}") for o in outputs]
    panels += [(f"worst_offset.{o}", f"worst static offset {label(o, units.get(o))}")
               for o in outputs]
    return [*panels, ("max_violation", "largest violation (signal units)"),
            ("step_ms_p99", "step p99 [ms]")]


def campaign_figure(path: str | Path, title: str, table: Any, violating: Sequence[float],
                    upper_bounds: Sequence[float], worst: Any = None,
                    worst_results: Path | None = None, signals: dict | None = None) -> None:
    """A campaign's ``report.png``, replaced atomically, for any number of inputs and outputs.

    Top: the share of violating runs per variant with its 95 % upper bound, and a box plot
    per KPI over the runs that finished (:func:`campaign_kpi_panels`). Below: the worst run,
    one panel per output (with its set-point and box) and per input (with its box).

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
        The worst run (``run``, ``variant``, ``violation_count``, ``max_violation``,
        ``iae.<o>``).
    worst_results : Path, optional
        Its ``results.csv``; a file that cannot be read is noted in the figure.
    signals : dict, optional
        A run's ``summary.json`` ``signals`` (outputs and inputs with unit, min, max); by
        default the outputs are those of the ``iae.<o>`` columns and the inputs those of the
        ``tv.<u>`` columns, without units or boxes.
    """
    plt = plots.pyplot()
    signals = signals or {}
    outputs = list(signals.get("outputs") or
                   [c[len("iae."):] for c in table.columns if c.startswith("iae.")])
    inputs = list(signals.get("inputs") or
                  [c[len("tv."):] for c in table.columns if c.startswith("tv.")])
    info = {**(signals.get("outputs") or {}), **(signals.get("inputs") or {})}
    units = {k: (v or {}).get("unit") or "" for k, v in info.items()}
    variants = list(dict.fromkeys(table["variant"]))
    ok = table[table["status"].isin(COMPLETE)]
    kpis = [(k, t) for k, t in campaign_kpi_panels(outputs, units) if k in table.columns]
    n_top = -(-(1 + len(kpis)) // 3)
    n_signals = max(1, len(outputs) + len(inputs))
    n_low = -(-n_signals // _worst_columns(n_signals)) if worst is not None else 0
    fig = plt.figure(figsize=(13, 2.9 * (n_top + n_low) + 0.8), layout="constrained")
    top, low = fig.subfigures(2, 1, height_ratios=[n_top, max(n_low, 1e-3)]) if n_low \
        else (fig, None)
    grid = top.add_gridspec(n_top, 3)
    ax = top.add_subplot(grid[0, 0])
    x = np.arange(len(variants))
    ax.bar(x, violating, color="C3", alpha=0.7, label="observed")
    ax.scatter(x, upper_bounds, color="k", marker="_", s=400, label="95 % upper bound")
    ax.set_xticks(x, variants, rotation=15, fontsize=8)
    ax.set_title("violating runs [%]", fontsize=10)
    ax.legend(fontsize=7)
    for i, (kpi, name) in enumerate(kpis, start=1):
        ax = top.add_subplot(grid[i // 3, i % 3])
        data = [ok[ok["variant"] == v][kpi].to_numpy(dtype=float) for v in variants]
        data = [d[np.isfinite(d)] for d in data]
        if any(d.size for d in data):
            ax.boxplot([d if d.size else [np.nan] for d in data], tick_labels=variants)
            ax.tick_params(axis="x", labelrotation=15, labelsize=8)
        ax.set_title(name, fontsize=10)
    if low is not None:
        _worst_run(low, worst, worst_results, outputs, inputs, info, units)
    fig.suptitle(title)
    plots.save(fig, path, dpi=90, atomic=True)


def _worst_columns(panels: int) -> int:
    """Columns of the worst run's panels: 2 for 2 or 4 panels, else 3."""
    return 2 if panels in (2, 4) else 3


def _worst_run(fig: Any, worst: Any, results: Path | None, outputs: list[str],
               inputs: list[str], info: dict, units: dict[str, str]) -> None:
    """The worst run's panels of :func:`campaign_figure` in the sub-figure ``fig``."""
    iae = ", ".join(f"{o} {worst[f'iae.{o}']:.4g} {plots.times_s(units.get(o))}"
                    for o in outputs if f"iae.{o}" in worst.index)
    fig.suptitle(f"worst run {int(worst['run']):06d}-{worst['variant']}: "
                 f"{int(worst['violation_count'])} violations"
                 + (f" (largest {worst['max_violation']:.3g})" if worst["violation_count"]
                    else "") + (f"; IAE {iae}" if iae else ""), fontsize=10)
    panels = [("y", o) for o in outputs] + [("u", u) for u in inputs]
    cols = _worst_columns(len(panels))
    grid = fig.add_gridspec(-(-max(1, len(panels)) // cols), cols)
    try:
        res = read_table(results)
    except Exception as exc:  # the figure must not fail the campaign
        ax = fig.add_subplot(grid[0, :])
        ax.text(0.5, 0.5, f"worst run not readable: {exc}", transform=ax.transAxes,
                ha="center")
        ax.set_axis_off()
        return
    names = set(res.names)

    def column(name: str) -> np.ndarray | None:
        return res.column(name) if name in names else None

    for i, (kind, name) in enumerate(panels):
        ax = fig.add_subplot(grid[i // cols, i % cols])
        entry = info.get(name) or {}
        plots.signal_panel(ax, res.time, column, kind, name, units.get(name),
                           (entry.get("min"), entry.get("max")))
        ax.set_xlabel("time [s]")


def run_folder_name(run: int, variant: str) -> str:
    """``runs/<run>-<variant>``: the folder of one run of one variant."""
    return f"{run:06d}-{variant}"
