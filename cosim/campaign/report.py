"""A campaign's tables and figures: ``runs.parquet``, ``summary.json``, ``report.png``.

Everything is computed from the run folders (``runs/<run>-<variant>/summary.json``), so a
resumed or interrupted campaign reports exactly the runs that are on disk.

``runs.parquet``: one row per run and variant with ``run``, ``seed``, ``variant``,
``status``, ``reason``, ``tries`` (1, or more when the run's worker process died under it and
the engine ran it again), one column per ``[draw]`` key (named exactly as in the spec), and the
KPIs :data:`KPI_COLUMNS`; for a GRU-model plant under the robust MPC also the theorem's checks
(:data:`THEOREM_COLUMNS`).

``summary.json``: ``runs``, ``ok``, ``failed``, ``retried_runs``, ``violating_runs`` and
``violation_probability_upper_95`` (one-sided Clopper-Pearson bound on the probability that
a run violates a constraint), per variant the same plus KPI quantiles, and the failures
grouped by reason.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from cosim import atomicio

__all__ = ["KPI_COLUMNS", "THEOREM_COLUMNS", "clopper_pearson_upper", "kpi_row",
           "run_folder_name", "summarize", "theorem_checks", "write_figure", "write_summary",
           "write_table"]

#: KPI columns of ``runs.parquet`` (besides run, seed, variant, status, reason, draws).
KPI_COLUMNS = ("violation_count", "max_violation", "iae_h1", "iae_h2", "worst_offset",
               "fallbacks", "suboptimal_steps", "setpoint_rejected_steps", "step_ms_p99",
               "steps", "wall_time_s")
#: What the paper's theorem promises, measured per run (GRU-model plant, robust MPC).
THEOREM_COLUMNS = ("initially_feasible", "infeasible_after_first", "fallbacks_after_first",
                   "observer_checks", "observer_bound_violations", "observer_error_max_ratio",
                   "final_offset", "final_state_error", "final_output_error")
#: KPIs summarised by quantiles in ``summary.json``.
QUANTILE_KPIS = ("iae_h1", "iae_h2", "worst_offset", "max_violation", "step_ms_p99",
                 "wall_time_s")
QUANTILES = (0.05, 0.5, 0.95, 1.0)
#: Status codes of an infeasible FHOCP in the robust MPC's ``ctrl.status`` column.
INFEASIBLE_CODES = (1.0, 2.0)


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
    """One ``runs.parquet`` row from a run's ``summary.json`` document."""
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
        "iae_h1": _float(_get(kpis, "iae", "h1")),
        "iae_h2": _float(_get(kpis, "iae", "h2")),
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
    return row


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
        ok = df[df["status"] == "ok"]
        ran = df[df["status"] != "interrupted"]
        violating = int((ran["violation_count"] > 0).sum())
        out: dict[str, Any] = {
            "runs": len(df), "ok": len(ok), "failed": int((df["status"] == "failed").sum()),
            "retried_runs": int((df["tries"] > 1).sum()) if "tries" in df else 0,
            "violating_runs": violating,
            "violation_probability_upper_95": clopper_pearson_upper(violating, len(ran)),
            "quantiles": {},
        }
        for kpi in QUANTILE_KPIS:
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
    from cosim.results import jsonable

    return jsonable(doc)


def write_table(table: Any, path: Path) -> None:
    """``runs.parquet`` (pyarrow), written atomically."""
    with atomicio.replacing(path) as tmp:
        table.to_parquet(tmp, index=False, engine="pyarrow")


def write_summary(doc: dict, path: Path) -> None:
    """``summary.json``, written atomically."""
    atomicio.write_text(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")


def write_figure(table: Any, runs_dir: Path, path: Path, title: str) -> None:
    """``report.png``: violations and KPI distributions per variant, the worst run.

    The share of violating runs per variant (with its :func:`clopper_pearson_upper` bound)
    and the worst run (largest violation, then largest IAE h1) are chosen here; the drawing
    is :func:`cosim.plots.campaign_figure`.
    """
    from cosim import plots

    shares, uppers = [], []
    for v in dict.fromkeys(table["variant"]):
        df = table[(table["variant"] == v) & (table["status"] != "interrupted")]
        k = int((df["violation_count"] > 0).sum())
        shares.append(100.0 * k / max(len(df), 1))
        uppers.append(100.0 * (clopper_pearson_upper(k, len(df)) or 0.0))
    ok = table[table["status"] == "ok"]
    worst, worst_results = None, None
    if len(ok):
        worst = ok.sort_values(["max_violation", "iae_h1"], ascending=False).iloc[0]
        worst_results = (runs_dir / run_folder_name(int(worst["run"]), str(worst["variant"]))
                         / "results.csv")
    plots.campaign_figure(path, title, table, shares, uppers, worst, worst_results)


def run_folder_name(run: int, variant: str) -> str:
    """``runs/<run>-<variant>``: the folder of one run of one variant."""
    return f"{run:06d}-{variant}"
