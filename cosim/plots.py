"""The run figure: outputs vs set-points with constraints, inputs with bounds (Agg backend).

In the style of the paper's Fig. 3: one panel per controlled output (plant value, measured
value if perturbed, set-point as a step line, the region outside the output constraints
shaded), one panel per manipulated input (with its bounds), and a dotted vertical line at
each perturbation time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.master import RunResult


def figure(path: str | Path, result: RunResult, title: str = "") -> Path:
    """Draw ``result`` into ``path`` (PNG) and return the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
