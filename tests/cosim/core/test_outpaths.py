"""Output-path checks: one-line errors naming the path and the option, nothing created."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.core.outpaths import figure_file, out_dir, out_file


def test_good_targets_pass_and_create_nothing(tmp_path: Path) -> None:
    assert out_dir(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert out_file(tmp_path / "c" / "d.csv") == tmp_path / "c" / "d.csv"
    assert figure_file(tmp_path / "e" / "f.PNG") == tmp_path / "e" / "f.PNG"
    assert list(tmp_path.iterdir()) == []


def test_bad_targets(tmp_path: Path) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    with pytest.raises(CosimError, match=r"blocker: --out must be a folder, but this is a file"):
        out_dir(blocker)
    with pytest.raises(CosimError, match=r"blocker/x/y: --res: '\S+blocker' is not a folder"):
        out_dir(blocker / "x" / "y", "--res")
    with pytest.raises(CosimError, match=r": --out must name a file, but this is a folder"):
        out_file(tmp_path)
    with pytest.raises(CosimError, match=r"f\.txt: --plot: unknown figure type '\.txt'"):
        figure_file(tmp_path / "f.txt")
    with pytest.raises(CosimError, match=r"f\.png: --fig: '\S+blocker' is not a folder"):
        figure_file(blocker / "f.png", "--fig")
    assert blocker.read_text() == "x"
