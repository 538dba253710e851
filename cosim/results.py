"""Writing a run to disk: ``results.csv``, ``summary.json`` (and the figure, via plots).

``results.csv`` follows the FMI cross-check CSV rules: comma separated, the header row holds
the column names in double quotes, ``time`` first, numbers unquoted in full precision
(Python ``repr``, which round-trips exactly), one row per communication point, no comments.
Column names are ``<source>.<signal>``: ``ref.h1`` (set-point), ``plant.h1`` (true plant
output, or a plant input/parameter the scenario sets), ``sensor.h1`` (measured value the
controller saw, only when the scenario perturbs it), ``ctrl.qa`` (controller output = plant
input), ``ctrl.<diagnostic>`` (controller diagnostics; ``nan`` where a step had none).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cosim import kpis as _kpis
from cosim.master import RunResult


def write_csv(path: Path, columns: list[str], rows: list[list[float]]) -> None:
    """Write rows in cross-check CSV format (see the module docstring)."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(",".join('"' + c.replace('"', '""') + '"' for c in columns) + "\n")
        rep = float.__repr__
        f.writelines(",".join([rep(float(v)) for v in row]) + "\n" for row in rows)


def summary(result: RunResult, meta: dict | None = None) -> dict:
    """The ``summary.json`` document of a run.

    Keys: ``status`` (``ok``/``failed``/``interrupted``), ``reason``, ``steps``,
    ``steps_planned``, ``step_size``, ``start_time``, ``stop_time``, ``wall_time_s``,
    ``kpis`` (see :func:`cosim.kpis.compute`), ``controller_summary`` (the controller's own
    ``summary()``: solver statistics), plus ``meta`` (scenario, plant, controller, seed...).
    """
    doc = {
        "status": result.status,
        "reason": result.reason,
        "steps": result.steps,
        "steps_planned": result.steps_planned,
        "step_size": result.step_size,
        "start_time": result.start_time,
        "stop_time": result.stop_time,
        "wall_time_s": round(result.wall_time_s, 6),
    }
    doc.update(meta or {})
    doc["kpis"] = _kpis.compute(result.columns, result.rows, result.outputs, result.references,
                                result.inputs, result.bounds)
    doc["controller_summary"] = result.controller_summary
    return _jsonable(doc)


def _jsonable(obj: object) -> object:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, bool | int | str) or obj is None:
        return obj
    try:
        f = float(obj)  # numpy scalars
    except (TypeError, ValueError):
        return str(obj)
    return f if math.isfinite(f) else None


def write(out_dir: str | Path, result: RunResult, meta: dict | None = None,
          figure: bool = True) -> dict:
    """Write ``results.csv``, ``summary.json`` and (optionally) ``figure.png`` into ``out_dir``.

    Wall-clock diagnostics (the controller's ``timing_diagnostics``, e.g. solve times) go to
    ``timings.csv`` (``time`` then one column each, one row per controller step), so that
    ``results.csv`` is identical across runs of the same scenario.

    The figure is best effort: a plotting error is recorded in the summary under
    ``figure_error`` instead of hiding the results.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "results.csv", result.columns, result.rows)
    if result.timing_columns:
        write_csv(out / "timings.csv", result.timing_columns, result.timing_rows)
    doc = summary(result, meta)
    if figure:
        try:
            from cosim import plots

            plots.figure(out / "figure.png", result, title=str((meta or {}).get("scenario", "")))
        except Exception as exc:  # pragma: no cover - plotting must not lose the results
            doc["figure_error"] = f"{type(exc).__name__}: {exc}"
    (out / "summary.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n",
                                      encoding="utf-8")
    return doc
