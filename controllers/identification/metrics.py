"""Accuracy of a model: open-loop simulation and the FIT index of the paper's section V.

The figure of a trained model is :func:`cosim.core.plots.identification_figure` (this numerical core
draws nothing).
"""

from __future__ import annotations

from collections.abc import Mapping
from itertools import pairwise

import numpy as np

from controllers import gru

__all__ = ["experiment_scores", "fit", "open_loop", "open_loop_experiments", "split_scores"]


def fit(y: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """FIT index per output, in percent.

    ``FIT = 100 (1 − ‖y − ξ‖₂ / ‖y − mean(y)‖₂)`` (section V of the paper), computed column
    by column for ``(T, p)`` arrays (or for one ``(T,)`` signal). A constant output has no
    FIT (NaN, or −inf when the prediction misses it).
    """
    y = np.asarray(y, dtype=float)
    xi = np.asarray(xi, dtype=float)
    num = np.linalg.norm(y - xi, axis=0)
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 100.0 * (1.0 - num / den)


def open_loop(p: Mapping[str, np.ndarray], u: np.ndarray, x0: np.ndarray | None = None
              ) -> np.ndarray:
    """Outputs ``ξ_0 … ξ_{T-1}`` of ``eq:gru`` driven by normalised inputs ``u`` (T, m).

    The model runs open loop (no measured output is used) from ``x0`` (default: zero).
    """
    n = p["U_z"].shape[0]
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    _, xi = gru.simulate(p, x0, np.asarray(u, dtype=float))
    return xi


def open_loop_experiments(p: Mapping[str, np.ndarray], u: np.ndarray,
                          experiment: np.ndarray | None = None) -> np.ndarray:
    """:func:`open_loop` restarted from ``x = 0`` at the first row of each experiment.

    ``experiment`` holds each row's experiment (consecutive rows; default: one experiment,
    the whole record): no experiment's state is carried into the next one.
    """
    u = np.asarray(u, dtype=float)
    if experiment is None:
        return open_loop(p, u)
    experiment = np.asarray(experiment)
    cuts = [0, *(np.flatnonzero(experiment[1:] != experiment[:-1]) + 1).tolist(), len(u)]
    return np.concatenate([open_loop(p, u[a:b]) for a, b in pairwise(cuts)])


def _scores(y: np.ndarray, xi: np.ndarray, split: np.ndarray
            ) -> dict[str, dict[str, list[float] | float]]:
    out: dict[str, dict[str, list[float] | float]] = {}
    for name in dict.fromkeys(split.tolist()):
        mask = split == name
        out[name] = {"fit": fit(y[mask], xi[mask]).tolist(),
                     "max_abs_err": float(np.max(np.abs(y[mask] - xi[mask])))}
    return out


def split_scores(p: Mapping[str, np.ndarray], u: np.ndarray, y: np.ndarray,
                 split: np.ndarray, experiment: np.ndarray | None = None
                 ) -> dict[str, dict[str, list[float] | float]]:
    """FIT per output and max absolute error per split, normalised units.

    The model is simulated open loop over the whole record from ``x = 0`` (inputs only),
    restarting from ``x = 0`` at each experiment (:func:`open_loop_experiments`), and each
    split's rows (of every experiment together) are scored; the transient from the arbitrary
    initial state lies at the start of the training split (of each experiment, when its
    training rows come first), so validation and test scores are free of it.

    Returns
    -------
    dict
        ``{split: {"fit": [per output], "max_abs_err": float}}``.
    """
    return _scores(y, open_loop_experiments(p, u, experiment), np.asarray(split))


def experiment_scores(p: Mapping[str, np.ndarray], u: np.ndarray, y: np.ndarray,
                      split: np.ndarray, experiment: np.ndarray
                      ) -> list[dict[str, dict[str, list[float] | float]]]:
    """:func:`split_scores` of each experiment on its own rows (in experiment order)."""
    xi = open_loop_experiments(p, u, experiment)
    split, experiment = np.asarray(split), np.asarray(experiment)
    return [_scores(y[experiment == e], xi[experiment == e], split[experiment == e])
            for e in dict.fromkeys(experiment.tolist())]
