"""Training records of one or several experiments: their stretches, the truncated training
subsequences cut from them, the windows of the open-loop evaluation, and the training
defaults that follow a record's length.

A record is a sequence of rows (one per sample), each with a split label (``train``, ``val``,
``test``) and an experiment index. A *stretch* is a maximal run of consecutive rows of one
split and one experiment. Training subsequences (paper, section V) are cut inside training
stretches only, so that none spans two experiments, or jumps over validation or test rows.
The open-loop evaluation restarts from ``x = 0`` at each experiment
(:func:`controllers.identification.metrics.open_loop_experiments`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.errors import DataError

__all__ = ["MAX_SEQ_LEN", "MIN_SEQ_LEN", "STEPS_PER_EPOCH", "RecordDefaults", "eval_windows",
           "record_defaults", "stretches", "subsequence_starts"]

#: Longest default subsequence: the paper's 500 steps.
MAX_SEQ_LEN = 500
#: Shortest default subsequence (unless the longest training stretch is shorter).
MIN_SEQ_LEN = 20
#: Default optimiser steps per epoch: the paper's 30 subsequences in batches of 5.
STEPS_PER_EPOCH = 6


def _experiment(split: np.ndarray, experiment: np.ndarray | None) -> np.ndarray:
    if experiment is None:
        return np.zeros(len(split), dtype=int)
    experiment = np.asarray(experiment)
    if experiment.shape != (len(split),):
        raise DataError(f"experiment has shape {experiment.shape}, expected ({len(split)},) "
                        "(one index per row)")
    return experiment


def stretches(split: np.ndarray, experiment: np.ndarray | None = None, name: str = "train"
              ) -> list[tuple[int, int]]:
    """``(start, end)`` row ranges of the maximal runs of split ``name`` in one experiment.

    Parameters
    ----------
    split : (T,) array of str
    experiment : (T,) array, optional
        Experiment of each row (default: one experiment).
    name : str
        The split.
    """
    split = np.asarray(split)
    exp = _experiment(split, experiment)
    inside = split == name
    out: list[tuple[int, int]] = []
    start = None
    for k in range(len(split) + 1):
        cont = (k < len(split) and inside[k] and start is not None and exp[k] == exp[k - 1])
        if start is not None and not cont:
            out.append((start, k))
            start = None
        if start is None and k < len(split) and inside[k]:
            start = k
    return out


def subsequence_starts(spans: Sequence[tuple[int, int]], seq_len: int,
                       stride: int | None = None) -> list[int]:
    """Start rows of the truncated subsequences of ``seq_len`` rows inside each stretch.

    Every ``stride`` rows (default ``seq_len``: non-overlapping) from each stretch's start, as
    long as the subsequence ends inside the stretch; a stretch shorter than ``seq_len`` gives
    none.

    Raises
    ------
    DataError
        No stretch is as long as ``seq_len``.
    """
    stride = stride or seq_len
    starts = [s for a, b in spans for s in range(a, b - seq_len + 1, stride)]
    if not starts:
        longest = max((b - a for a, b in spans), default=0)
        raise DataError(f"the longest training stretch has {longest} steps, fewer than "
                        f"seq_len = {seq_len}")
    return starts


def eval_windows(split: np.ndarray, experiment: np.ndarray | None, name: str,
                 washout: int) -> list[tuple[int, int]]:
    """Open-loop windows scoring split ``name``: one per experiment that has such rows.

    Each window starts from ``x = 0`` ``washout`` rows before the experiment's first ``name``
    row (not before the experiment's first row) and ends after its last ``name`` row.
    """
    split = np.asarray(split)
    exp = _experiment(split, experiment)
    out = []
    for e in dict.fromkeys(exp.tolist()):
        rows = np.flatnonzero(exp == e)
        hit = rows[split[rows] == name]
        if hit.size:
            out.append((max(int(rows[0]), int(hit[0]) - washout), int(hit[-1]) + 1))
    return out


@dataclass(frozen=True)
class RecordDefaults:
    """Subsequence length, washout and batch of a record (:func:`record_defaults`)."""

    seq_len: int
    washout: int
    batch: int
    subsequences: int


def record_defaults(lengths: Sequence[int], seq_len: int | None = None,
                    washout: int | None = None, batch: int | None = None,
                    stride: int | None = None) -> RecordDefaults:
    """The training settings that follow the record's length, where not given.

    With ``T`` training rows in stretches of ``lengths``:

    * ``seq_len = min(500, max(20, T // 10), longest stretch)``: at least about ten
      subsequences on a short record, the paper's 500 from 5,000 training rows on;
    * ``washout = seq_len // 10`` (50 for 500);
    * ``batch = max(1, round(S / 6))`` for the ``S`` subsequences: six optimiser steps per
      epoch, as the paper's 30 subsequences in batches of 5.

    15,000 training rows in one stretch (``cosim generate-data``'s default) give the paper's
    500 / 50 / 5.
    """
    total = int(sum(lengths))
    longest = int(max(lengths, default=0))
    if seq_len is None:
        seq_len = max(1, min(MAX_SEQ_LEN, max(MIN_SEQ_LEN, total // 10), longest))
    if washout is None:
        washout = seq_len // 10
    step = stride or seq_len
    count = sum(max(0, (n - seq_len) // step + 1) for n in lengths)
    if batch is None:
        batch = max(1, round(count / STEPS_PER_EPOCH))
    return RecordDefaults(seq_len=seq_len, washout=washout, batch=batch, subsequences=count)
