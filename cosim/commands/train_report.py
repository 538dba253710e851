"""What ``cosim train`` tells about the model it trained: scores, the linear baseline, the
figure, the model file's ``training`` block (:mod:`cosim.commands.train` runs the training).

Every score is a free-run simulation (:mod:`controllers.identification.simulation`), in the
outputs' units, per split and per experiment, beside the ARX baseline fitted on the same
training rows (:mod:`controllers.identification.linear`); a model worse than its baseline on
validation says so in one line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Evaluation", "evaluate", "figure", "print_report"]


@dataclass
class Evaluation:
    """The trained model and its baseline, scored on the record."""

    xi: np.ndarray                       # the model's free run (normalised)
    scores: dict[str, Any]
    baseline: dict[str, Any] | None      # the ARX model's scores (None: too few rows)
    baseline_xi: np.ndarray | None
    baseline_orders: dict[str, int] | None
    comparison: dict[str, Any]
    warning: str | None
    limits: dict[str, Any] = field(default_factory=dict)
    #: each experiment's initial state of the free run (by index), estimated once
    starts: dict[int, np.ndarray] = field(default_factory=dict)
    #: With measured disturbances: the same score with them held at their training mean
    #: (what the model would simulate without measuring them), and the ratio of the two.
    disturbances: dict[str, Any] | None = None


def evaluate(params: dict[str, np.ndarray], record: Any, problem: Any,
             experiment_names: list[str | None], x0_samples: int,
             arx: Any = False) -> Evaluation:
    """Score the model and fit and score its ARX baseline on ``record``
    (:class:`controllers.identification.record.Record`, normalised by ``problem``); ``arx``:
    the baseline when it was fitted already (``None``: the record has too few rows for one),
    ``False``: fit it here."""
    from controllers.identification import linear, report
    from controllers.identification.simulation import simulate

    norm = problem.normalization()
    scale, names = np.asarray(norm["y_scale"]), list(problem.output_names)
    starts: dict[int, np.ndarray] = {}
    xi = simulate(params, record, x0_samples, starts)
    ours = report.scores(record, xi, scale, names, experiment_names)
    arx = linear.fit_arx(record) if arx is False else arx
    theirs = bxi = orders = None
    if arx is not None:
        bxi = linear.simulate(arx, record)
        theirs = report.scores(record, bxi, scale, names, experiment_names)
        orders = {"na": arx.na, "nb": arx.nb, "nk": arx.nk}
    comparison = report.compare(ours, theirs, scale, names)
    return Evaluation(xi=xi, scores=ours, baseline=theirs, baseline_xi=bxi,
                      baseline_orders=orders, comparison=comparison,
                      warning=report.verdict(comparison),
                      limits=record.limits.to_dict(names, scale, np.asarray(norm["y_offset"])),
                      starts=starts,
                      disturbances=_without_disturbances(params, record, problem.q, ours,
                                                         comparison, x0_samples, scale, names))


def _without_disturbances(params: dict[str, np.ndarray], record: Any, q: int,
                          ours: dict[str, Any], comparison: dict[str, Any], x0_samples: int,
                          scale: np.ndarray, names: list[str]) -> dict[str, Any] | None:
    """What measuring the ``q`` disturbances (the last model inputs) is worth: the free run
    with every disturbance held at its training mean, scored on the comparison's split,
    beside the model's own score (``None`` without disturbances)."""
    from dataclasses import replace

    from controllers.identification import report
    from controllers.identification.simulation import simulate

    if not q:
        return None
    u = record.u.copy()
    u[:, -q:] = np.mean(u[record.split == "train", -q:], axis=0)
    held = simulate(params, replace(record, u=u), x0_samples)
    split = comparison["split"]
    theirs = report.scores(record, held, scale, names)
    mine = report.mean_rms(ours, split, scale, names)
    without = report.mean_rms(theirs, split, scale, names)
    return {"split": split, "held_at": "training mean", "rms": theirs["splits"][split]["rms"],
            "ratio": without / mine if mine > 0 else None}


def _cells(doc: dict[str, Any], names: list[str], units: list[str]) -> str:
    return ", ".join(
        f"{n} {_num(doc['rms'][n])} {u}".rstrip() + f" (FIT {_num(doc['fit'][n], '.1f')} %)"
        for n, u in zip(names, units, strict=True))


def _num(v: float | None, fmt: str = ".4g") -> str:
    return "n/a" if v is None else format(v, fmt)


def print_report(ev: Evaluation, names: list[str], units: list[str]) -> None:
    """The scores, split by split (and experiment by experiment), GRU beside ARX."""
    print("free-run simulation, RMS in the outputs' units (FIT): each experiment from the "
          "state estimated from its first samples")
    for split, doc in ev.scores["splits"].items():
        print(f"  {split:5s} GRU  {_cells(doc, names, units)}")
        if ev.baseline is not None:
            print(f"  {'':5s} ARX  {_cells(ev.baseline['splits'][split], names, units)}")
    for k, exp in enumerate(ev.scores.get("experiments", [])):
        label = exp["name"] if exp["name"] is not None else f"#{k + 1}"
        for split, doc in exp["splits"].items():
            line = f"  experiment {label}, {split}: GRU {_cells(doc, names, units)}"
            if ev.baseline is not None:
                base = ev.baseline["experiments"][k]["splits"][split]
                line += f"; ARX {_cells(base, names, units)}"
            print(line)
    if ev.limits:
        print("  sensor limits found (read as 'at or beyond'): " + "; ".join(
            f"{n} {k} {v:.6g}" for n, lim in ev.limits.items() for k, v in lim.items()))
    d = ev.disturbances
    if d is not None:
        held = ", ".join(f"{n} {_num(d['rms'][n])} {u}".rstrip()
                         for n, u in zip(names, units, strict=True))
        ratio = "" if d["ratio"] is None else f": {d['ratio']:.2f}x the error with them"
        print(f"  {d['split']:5s} GRU with the measured disturbances held at their "
              f"{d['held_at']}: {held}{ratio}")
    if ev.warning:
        print(f"warning: {ev.warning}")


def figure(path: str | Path, ev: Evaluation, record: Any, model: Any, logged: bool,
           title: str) -> None:
    """Every row of the record: measured, the GRU's and the ARX's free runs, the splits
    shaded (:func:`cosim.core.plots.identification_figure`)."""
    from cosim.core import plots

    plots.identification_figure(
        path, model.denormalize_y(record.y), model.denormalize_y(ev.xi),
        None if ev.baseline_xi is None else model.denormalize_y(ev.baseline_xi),
        record.split, record.experiment, list(model.output_names),
        list(model.output_units), float(model.Ts),
        "measured (log)" if logged else "measured (plant FMU)", title)
