"""The controller's predictions against the plant: the k-step prediction error of a
commissioning in shadow (issue 61, goal 5; docs: guide/operating.md, "Commissioning in
shadow").

Before an engineer lets an MPC write to a plant, they run it in manual (``op.mode = 0``):
it reads, estimates and predicts, the operator's inputs drive the plant, and its
predictions are compared with what the plant then does (AspenTech DMC3's accumulated
prediction error per CV). :class:`PredictionWatch` keeps, each step ``k``, the outputs the
controller's plan predicts for ``k + 1 … k + N`` (the model's outputs along the FHOCP's plan,
the problem's units) and, as the plant's outputs arrive, the error ``e_i = y_{k+i} −
ŷ_{k+i|k}`` for each ``i``: per output, the mean and the RMS over every step and ``i``, and
the RMS at each ``i`` (over the horizon). In manual the plan is not what the plant gets, so
the predictions are made again each step from the plant's inputs held (the plan's first
input replaced): ``ŷ_{k+i|k}`` is then the prediction of the inputs the plant actually got
when they were held, the error the model's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PredictionWatch"]


class PredictionWatch:
    """The k-step prediction errors of one run (module docstring).

    Parameters
    ----------
    outputs : list of str
        The outputs' names.
    horizon : int
        ``N``: predictions ``1 … N`` steps ahead.
    """

    def __init__(self, outputs: list[str], horizon: int) -> None:
        self.outputs = list(outputs)
        self.N = int(horizon)
        self.reset()

    def reset(self) -> None:
        """A new run."""
        p = len(self.outputs)
        # the last N predictions in a ring: the one made at step s in slot s % N, its rows
        # beyond its length not filled
        self._ring = np.zeros((self.N, self.N, p))
        self._filled = np.zeros((self.N, self.N), dtype=bool)
        self._sum = np.zeros((self.N, p))
        self._sq = np.zeros((self.N, p))
        self._count = np.zeros(self.N, dtype=int)
        self._ages = np.arange(self.N)
        self.steps = 0

    def measure(self, y: np.ndarray) -> None:
        """The plant's outputs now (problem units): scored against each prediction of
        them still pending (made ``1 … N`` steps ago), all at once (one add per age, as
        one at a time would)."""
        y = np.asarray(y, dtype=float)
        ages = self._ages[:min(self.steps, self.N)]          # age 0: made last step
        slots = (self.steps - 1 - ages) % self.N
        kept = self._filled[slots, ages]
        scored = ages[kept]
        if scored.size == 0:
            return
        e = y - self._ring[slots[kept], scored]
        self._sum[scored] += e
        self._sq[scored] += e * e
        self._count[scored] += 1

    def predict(self, y_pred: np.ndarray) -> None:
        """This step's predictions (``N'`` × p, ``N' ≤ N``: ``ŷ_{k+1|k} …``)."""
        pred = np.asarray(y_pred, dtype=float)[:self.N]
        slot = self.steps % self.N
        self._ring[slot, :pred.shape[0]] = pred
        self._filled[slot] = self._ages < pred.shape[0]
        self.steps += 1

    def last_prediction(self) -> dict[str, list[float]]:
        """The last step's predictions ``ŷ_{k+1|k} … ŷ_{k+N|k}`` by output (empty before
        the first)."""
        if not self.steps:
            return {}
        slot = (self.steps - 1) % self.N
        last = self._ring[slot, self._filled[slot]]
        return {name: last[:, j].tolist() for j, name in enumerate(self.outputs)}

    def summary(self) -> dict[str, Any]:
        """Per output: ``mean``, ``rms`` (over every step and horizon) and ``rms_by_step``
        (index ``i − 1``: ``i`` steps ahead, as far as the run scored), and how many steps
        predicted."""
        out: dict[str, Any] = {"steps": self.steps, "horizon": self.N, "outputs": {}}
        n = self._count[:, None]
        total = int(self._count.sum())
        scored = int(np.count_nonzero(self._count))
        for j, name in enumerate(self.outputs):
            by_step = [float(np.sqrt(self._sq[i, j] / n[i, 0])) for i in range(scored)]
            out["outputs"][name] = {
                "mean": float(self._sum[:, j].sum() / total) if total else None,
                "rms": float(np.sqrt(self._sq[:, j].sum() / total)) if total else None,
                "rms_by_step": by_step}
        return out
