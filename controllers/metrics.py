"""Accuracy of a model: open-loop simulation and the FIT index of the paper's section V.

The figure of a prediction is :func:`cosim.plots.prediction_figure` (this numerical core
draws nothing).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from controllers import gru

__all__ = ["fit", "open_loop", "split_scores"]


def fit(y: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """FIT index per output, in percent.

    ``FIT = 100 (1 − ‖y − ξ‖₂ / ‖y − mean(y)‖₂)`` (section V of the paper), computed column
    by column for ``(T, p)`` arrays (or for one ``(T,)`` signal).
    """
    y = np.asarray(y, dtype=float)
    xi = np.asarray(xi, dtype=float)
    num = np.linalg.norm(y - xi, axis=0)
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
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


def split_scores(p: Mapping[str, np.ndarray], u: np.ndarray, y: np.ndarray,
                 split: np.ndarray) -> dict[str, dict[str, list[float] | float]]:
    """FIT per output and max absolute error per split, normalised units.

    The model is simulated open loop over the whole record from ``x = 0`` (inputs only), and
    each split's rows are scored; the transient from the arbitrary initial state lies at the
    start of the training split, so validation and test scores are free of it.

    Returns
    -------
    dict
        ``{split: {"fit": [per output], "max_abs_err": float}}``.
    """
    xi = open_loop(p, u)
    out: dict[str, dict[str, list[float] | float]] = {}
    for name in dict.fromkeys(split.tolist()):
        mask = split == name
        out[name] = {"fit": fit(y[mask], xi[mask]).tolist(),
                     "max_abs_err": float(np.max(np.abs(y[mask] - xi[mask])))}
    return out
