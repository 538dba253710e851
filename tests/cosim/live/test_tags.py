"""Tags files: node ids and browse paths parsed, every fault one line naming file and line."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.live import tags

SIGNALS = ["qa", "qb", "h1", "h2"]


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plant.tags.toml"
    path.write_text(text)
    return path


def test_node_ids_browse_paths_and_defaults(tmp_path: Path) -> None:
    t = tags.load(write(tmp_path, 'root = "2:Plant/Area1"\n[tags]\nh1 = "ns=2;s=LIC101.PV"\n'
                                  'h2 = "2:Tanks/LT102"\nqa = "/2:Pumps/P1"\nqb = "i=2258"\n'),
                  SIGNALS)
    assert t.root == ((2, "Plant"), (None, "Area1"))
    assert t.tag("h1").node_id == "ns=2;s=LIC101.PV"
    assert t.tag("h2").path == ((2, "Tanks"), (None, "LT102")) and not t.tag("h2").absolute
    assert t.tag("qa").absolute and t.tag("qa").describe() == "/2:Pumps/P1"
    assert t.tag("qb").node_id == "i=2258"
    assert tags.Tags().tag("h1").path == ((None, "h1"),)     # untagged: its own name


@pytest.mark.parametrize(("text", "line", "words"), [
    ('[tags]\nh1 = "ns=2;s=A"\nlevel = "x"\n', 3, "'level' is not a signal of the problem"),
    ('[tags]\nh1 = 3\n', 2, "must be a node id"),
    ('[tags]\nh1 = "ns=x;s=A"\n', 2, "node id 'ns=x;s=A'"),
    ('[tags]\nh1 = "2:A//B"\n', 2, "segment ''"),
    ('unknown = 1\n', 1, "unknown key 'unknown'"),
    ('[tags]\nh1 = "a"\nh1 = "b"\n', 3, "invalid TOML"),
])
def test_faults_name_file_and_line(tmp_path: Path, text: str, line: int, words: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(CosimError) as err:
        tags.load(path, SIGNALS)
    assert str(err.value).startswith(f"{path}:{line}:") and words in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match="tags file not found"):
        tags.load(tmp_path / "none.toml", SIGNALS)
