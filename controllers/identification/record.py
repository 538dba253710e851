"""A normalised identification record: inputs, outputs, split, experiments, sensor limits.

The training and the scoring of :mod:`controllers.identification` take one :class:`Record`:
the rows of one or several experiments (consecutive rows; an experiment is one time series:
no state is carried from one into the next), each row labelled ``train``, ``val`` or
``test``, the outputs' sensor limits (:mod:`controllers.identification.saturation`) and each
sample's flag at them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from controllers.identification.saturation import SensorLimits, detect, flags

__all__ = ["SPLITS", "Record"]

#: The split labels, in order.
SPLITS = ("train", "val", "test")


@dataclass
class Record:
    """Normalised rows of one or several experiments.

    Attributes
    ----------
    u, y : (T, m), (T, p) arrays
        Normalised inputs and outputs (row k: u_k applied over [t_k, t_k + Ts), y_k
        measured at t_k: the timing of ``eq:gru``).
    split : (T,) array of str
        ``train``, ``val`` or ``test`` per row.
    experiment : (T,) int array
        The experiment of each row (consecutive rows).
    limits : SensorLimits
        The outputs' sensor limits (default: found in the training rows,
        :func:`controllers.identification.saturation.detect`).
    """

    u: np.ndarray
    y: np.ndarray
    split: np.ndarray
    experiment: np.ndarray
    limits: SensorLimits | None = None
    sat: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.u = np.asarray(self.u, dtype=float)
        self.y = np.asarray(self.y, dtype=float)
        self.split = np.asarray(self.split)
        self.experiment = np.asarray(self.experiment)
        T = len(self.u)
        if self.y.shape[0] != T or self.split.shape != (T,) or self.experiment.shape != (T,):
            raise ValueError(f"record arrays disagree in length: u {self.u.shape}, y "
                             f"{self.y.shape}, split {self.split.shape}, experiment "
                             f"{self.experiment.shape}")
        if self.limits is None:
            self.limits = detect(self.y, self.split == "train")
        self.sat = flags(self.y, self.limits)

    @property
    def m(self) -> int:
        return int(self.u.shape[1])

    @property
    def p(self) -> int:
        return int(self.y.shape[1])

    def experiments(self) -> list[tuple[int, int]]:
        """``(start, end)`` row ranges of the experiments, in order."""
        e = self.experiment
        cuts = [0, *(np.flatnonzero(e[1:] != e[:-1]) + 1).tolist(), len(e)]
        return list(pairwise(cuts))

    def stretches(self, name: str = "train") -> list[tuple[int, int]]:
        """``(start, end)`` of the maximal runs of split ``name`` inside one experiment."""
        out = []
        for a, b in self.experiments():
            inside = self.split[a:b] == name
            k = 0
            while k < b - a:
                if not inside[k]:
                    k += 1
                    continue
                j = k
                while j < b - a and inside[j]:
                    j += 1
                out.append((a + k, a + j))
                k = j
        return out

    def has(self, name: str) -> bool:
        """Whether some row is in split ``name``."""
        return bool(np.any(self.split == name))
