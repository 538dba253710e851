"""Checks of output paths (``--out``, ``--plot``, ``--figure``) before any work is done.

A command that would compute for minutes and then fail to write its result checks the
target first: each helper raises a one-line :class:`~cosim.core.errors.CosimError` naming the
path and the option (an :class:`~cosim.core.errors.OutputError`, exit 1, when the folder is not
writable). Nothing is created here (a failed command leaves no empty folder);
the writer creates missing folders.
"""

from __future__ import annotations

import os
from pathlib import Path

from cosim.core.errors import CosimError, OutputError

__all__ = ["FIGURE_SUFFIXES", "figure_file", "out_dir", "out_file"]

#: File types a figure option can write (matplotlib's, by file name suffix).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".eps", ".ps", ".tif",
                   ".tiff", ".webp", ".gif")


def _check_parents(folder: Path, path: Path, option: str) -> None:
    """The nearest existing ancestor of ``folder`` (itself included) must be a writable
    folder; nothing is created."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise CosimError(f"{path}: {option}: '{probe}' is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        # an unwritable target is an output failure (exit 1), like a full disk
        raise OutputError(f"{path}: cannot write: {option}: the folder '{probe}' is not "
                          "writable")


def out_dir(path: str | Path, option: str = "--out") -> Path:
    """Check that the output folder ``path`` exists or can be created."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise CosimError(f"{path}: {option} must be a folder, but this is a file")
    _check_parents(path, path, option)
    return path


def out_file(path: str | Path, option: str = "--out") -> Path:
    """Check that the file ``path`` can be written (its folder exists or can be created)."""
    path = Path(path)
    if path.is_dir():
        raise CosimError(f"{path}: {option} must name a file, but this is a folder")
    _check_parents(path.parent, path, option)
    return path


def figure_file(path: str | Path, option: str = "--plot") -> Path:
    """:func:`out_file` for a figure, whose suffix must be a matplotlib file type."""
    path = Path(path)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise CosimError(f"{path}: {option}: unknown figure type '{path.suffix}' (use one of "
                         f"{', '.join(FIGURE_SUFFIXES)})")
    return out_file(path, option)
