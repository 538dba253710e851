"""A campaign's output folder: ``campaign.json``, one folder per run, and the reports.

Everything a campaign reports is rebuilt from the run folders (:func:`build_report`), so a
campaign stopped half-way and resumed (``--resume``: only the runs not on disk yet) reports
exactly what is on disk. ``campaign.json`` holds the spec and its fingerprint (the spec's text
and every input file); a resume with another fingerprint is refused.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.campaign import report
from cosim.campaign.cluster import lost_worker
from cosim.campaign.spec import CampaignSpec
from cosim.core import atomicio
from cosim.core.errors import CosimError
from cosim.core.run_result import COMPLETE

if TYPE_CHECKING:
    from cosim.campaign.plan import Plan

__all__ = ["CAMPAIGN_FILES", "TRACEBACK_FILE", "build_report", "finished", "open_folder",
           "write_run"]

#: Files of a campaign folder (besides ``runs/``).
CAMPAIGN_FILES = ("campaign.json", "runs.parquet", "summary.json", "report.png")
#: The traceback of an internal error that ended a run, in its folder (for a bug report).
TRACEBACK_FILE = "traceback.txt"


def finished(runs_dir: Path, task: dict[str, Any]) -> bool:
    """Whether the task's run folder holds a complete run (``ok`` or ``failed``)."""
    path = runs_dir / report.run_folder_name(task["run"], task["variant"]) / "summary.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return doc.get("status") in (*COMPLETE, "failed")


def open_folder(plan: Plan, out: Path, resume: bool, force: bool) -> list[dict[str, Any]]:
    """Check or start ``campaign.json``; returns the tasks still to run."""
    spec = plan.spec
    marker = out / "campaign.json"
    runs_dir = out / "runs"
    if marker.exists() and not (resume or force):
        raise CosimError(f"{out}: holds a campaign already; --resume to finish it, --force to "
                         "start it over, or choose another --out")
    if marker.exists() and resume:
        try:
            old = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise CosimError(f"{marker}: unreadable ({exc}); use --force to start over") \
                from None
        if old.get("fingerprint") != plan.fingerprint:
            raise CosimError(f"{out}: --resume: the spec or its input files changed since this "
                             "campaign started (fingerprint differs); use --force to start "
                             "over or another --out")
    elif force:
        shutil.rmtree(runs_dir, ignore_errors=True)
        for name in CAMPAIGN_FILES:
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
    doc = {"name": spec.name, "fingerprint": plan.fingerprint, "runs": spec.runs,
           "seed": spec.seed, "variants": [v.name for v in spec.variants],
           "timeout_s": plan.timeout, "spec_file": str(spec.path), "spec": spec.text}
    atomicio.write_text(marker, json.dumps(doc, indent=2) + "\n")
    runs_dir.mkdir(parents=True, exist_ok=True)
    return [t for t in plan.tasks if not (resume and finished(runs_dir, t))]


def write_run(out: Path, spec: CampaignSpec, task: dict[str, Any],
              outcome: dict[str, Any] | None, error: BaseException | None) -> str:
    """Write one run's folder (as ``cosim run`` does); returns its status.

    ``outcome`` is what :func:`~cosim.campaign.task.run_task` returned, or ``None`` when the
    task ended with ``error`` on the cluster (its worker died in every try). ``task["tries"]``
    (default 1): the tries it took (:mod:`cosim.campaign.engine`). The run's
    ``summary.json`` records them under ``campaign.tries``; the
    traceback of an internal error goes to ``traceback.txt`` beside it (removed when the run
    has none).
    """
    from cosim.core import results
    from cosim.core.master import RunResult

    tries = int(task.get("tries", 1))
    if outcome is None:
        reason = _error_reason(error, task)
        result = RunResult(columns=["time"], rows=[], status="failed", reason=reason)
        theorem = None
        trace = None if error is None or lost_worker(error) else "".join(
            traceback.format_exception(error))
    else:
        result = outcome["result"]
        rows = np.asarray(result.rows, dtype=float)
        result.rows = rows.tolist()
        theorem = outcome.get("theorem")
        trace = outcome.get("traceback")
    draw = task["draw"]
    meta: dict[str, Any] = {
        "scenario": task["scenario_name"], "plant": str(spec.plant or "project FMU"),
        "controller": task["controller"], "controller_options": task["options"],
        "seed": draw["seed"],
        "campaign": {"name": spec.name, "run": task["run"], "variant": task["variant"],
                     "tries": tries, "draws": draw["values"], "setpoints": draw["setpoints"],
                     "plant_start": draw["plant_start"],
                     **({"disturbances": draw["disturbances"]} if draw.get("disturbances")
                        else {}),
                     **({"operator": draw["operator"]} if draw.get("operator") else {})},
    }
    folder = out / "runs" / report.run_folder_name(task["run"], task["variant"])
    if theorem is not None:
        from cosim.core import kpis

        k = kpis.compute(result.columns, result.rows, result.outputs, result.references,
                         result.inputs, result.bounds)
        meta["campaign"]["theorem"] = report.theorem_checks(
            result.columns,
            np.asarray(result.rows, dtype=float).reshape(len(result.rows), len(result.columns)),
            theorem, k)
    results.write(folder, result, meta, figure=spec.figures)
    if trace:
        atomicio.write_text(folder / TRACEBACK_FILE, trace)
    else:
        with contextlib.suppress(FileNotFoundError):
            (folder / TRACEBACK_FILE).unlink()
    return result.status


def _error_reason(error: BaseException | None, task: dict[str, Any]) -> str:
    """The reason of a run whose task ended with ``error`` on the cluster."""
    if lost_worker(error):
        tries = int(task.get("tries", 1))
        if tries == 0:
            return (f"lost with its worker process {task.get('lost_unstarted', 0)} times "
                    "before it started (workers keep dying)")
        each = f"in each of its {tries} tries" if tries > 1 else "in its only try"
        return (f"the run killed its worker process {each} (a crash in native code, or "
                f"stuck past its timeout of {task['timeout']:g} s)")
    if error is None:
        return "on the Dask cluster: no result and no error"
    return "on the Dask cluster: " + " ".join(f"{type(error).__name__}: {error}".split())


def build_report(spec: CampaignSpec, out: Path, write: bool = True) -> tuple[Any, dict]:
    """Rebuild ``runs.parquet``, ``summary.json`` and ``report.png`` from the run folders."""
    import pandas as pd

    rows = []
    keys = [d.key for d in spec.draws]
    for run in range(spec.runs):
        for v in spec.variants:
            path = out / "runs" / report.run_folder_name(run, v.name) / "summary.json"
            try:
                doc = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            rows.append(report.kpi_row(doc, keys))
    columns = ["run", "seed", "variant", "status", "reason", "tries", *keys,
               *report.KPI_COLUMNS]
    table = pd.DataFrame(rows, columns=None if rows else columns)
    summary = report.summarize(table, spec.name, spec.runs * len(spec.variants)) if rows \
        else {"campaign": spec.name, "planned": spec.runs * len(spec.variants), "runs": 0}
    if write:
        report.write_table(table, out / "runs.parquet")
        report.write_summary(summary, out / "summary.json")
        if rows:
            report.write_figure(table, out / "runs", out / "report.png",
                                f"campaign {spec.name}: {len(table)} runs")
    return table, summary
