"""What a trained model is worth, in the outputs' own units: simulation RMS and FIT per split
and per experiment, next to the linear baseline scored the same way.

Every number here comes from a free-run simulation (:func:`controllers.identification.
simulation.simulate`: each experiment from the initial state estimated from its first
samples, read through the sensor limits), never from one-step-ahead prediction, so that a
model that only follows its input looks as poor as it is.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.identification.metrics import fit
from controllers.identification.record import SPLITS, Record

__all__ = ["compare", "mean_rms", "scores", "verdict"]


def _split_scores(y: np.ndarray, xi: np.ndarray, mask: np.ndarray, scale: np.ndarray,
                  names: list[str]) -> dict[str, Any]:
    err = y[mask] - xi[mask]
    r = np.sqrt(np.mean(err ** 2, axis=0)) * np.abs(scale)
    f = fit(y[mask], xi[mask])
    return {"rows": int(np.count_nonzero(mask)),
            "rms": {n: _finite(v) for n, v in zip(names, r, strict=True)},
            "fit": {n: _finite(v) for n, v in zip(names, f, strict=True)}}


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def scores(record: Record, xi: np.ndarray, scale: np.ndarray, names: list[str],
           experiment_names: list[str | None] | None = None) -> dict[str, Any]:
    """``{"splits": {split: {"rows", "rms": {output: value}, "fit": {output: %}}},
    "experiments": [{"name", "splits": {…}}]}``: RMS in the outputs' units (``scale``: the
    normalisation's scale per output), FIT in percent; every split with rows, pooled over the
    experiments, and each experiment's own (when there are several)."""
    out: dict[str, Any] = {"splits": {}}
    for name in SPLITS:
        mask = record.split == name
        if np.any(mask):
            out["splits"][name] = _split_scores(record.y, xi, mask, scale, names)
    spans = record.experiments()
    if len(spans) > 1:
        labels = experiment_names or [None] * len(spans)
        out["experiments"] = []
        for (a, b), label in zip(spans, labels, strict=True):
            rows = np.zeros(len(record.y), dtype=bool)
            rows[a:b] = True
            per = {s: _split_scores(record.y, xi, rows & (record.split == s), scale, names)
                   for s in SPLITS if np.any(rows & (record.split == s))}
            out["experiments"].append({"name": label, "splits": per})
    return out


def mean_rms(doc: dict[str, Any], split: str, scale: np.ndarray, names: list[str]) -> float:
    """Mean over the outputs of the split's RMS, normalised by each output's scale."""
    rms = doc["splits"][split]["rms"]
    vals = [rms[n] / abs(s) if rms[n] is not None else math.inf
            for n, s in zip(names, scale, strict=True)]
    return float(np.mean(vals))


def compare(model: dict[str, Any], baseline: dict[str, Any] | None, scale: np.ndarray,
            names: list[str]) -> dict[str, Any]:
    """The model against the baseline on the first of validation, test, training that has
    rows: ``{"split", "model", "baseline", "ratio"}`` (mean normalised RMS; ``ratio`` model /
    baseline, ``None`` without a baseline)."""
    split = next(s for s in ("val", "test", "train") if s in model["splits"])
    ours = mean_rms(model, split, scale, names)
    theirs = None if baseline is None else mean_rms(baseline, split, scale, names)
    ratio = (ours / theirs if theirs is not None and theirs > 0 and math.isfinite(theirs)
             else None)
    return {"split": split, "model": ours, "baseline": theirs, "ratio": ratio}


def verdict(comparison: dict[str, Any]) -> str | None:
    """One line when the model is worse than its linear baseline, else ``None``."""
    ratio = comparison["ratio"]
    if ratio is None or ratio <= 1.0:
        return None
    word = {"val": "validation", "test": "test", "train": "training"}[comparison["split"]]
    return (f"the GRU simulates the {word} rows worse than its linear (ARX) baseline "
            f"({ratio:.2f}x its RMS): more data, more epochs or another excitation would be "
            "needed before it is worth more than a linear model")
