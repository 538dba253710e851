"""The tests' TOML writer (:mod:`tests.toml_text`): what it writes reads back as the document
it was given, in the layout its docstring shows."""

from __future__ import annotations

import doctest
import math
import tomllib
from pathlib import Path

from tests import toml_text
from tests.toml_text import campaign_spec


def test_the_text_reads_back_as_the_document() -> None:
    doc = {"title": "a \"quoted\" name: ünits", "problem": {"Ts": 20.0, "on": True},
           "inputs.P": {"min": -1e-6, "max": math.inf, "hold": [3, 60]},
           "draw": {"plant.a1": {"normal": [1.31e-4, 2e-6]}, "path": Path("a/b.csv")},
           "variant": [{"name": "a"}, {"name": "b", "options": {"law": "paper"}}]}
    want = {"title": doc["title"], "problem": doc["problem"],
            "inputs": {"P": doc["inputs.P"]},
            "draw": {"plant.a1": doc["draw"]["plant.a1"], "path": "a/b.csv"},
            "variant": doc["variant"]}
    assert tomllib.loads(toml_text.toml_text(doc)) == want


def test_the_docstrings_example_holds() -> None:
    result = doctest.testmod(toml_text)
    assert result.attempted > 0 and result.failed == 0


def test_a_campaign_spec_has_only_the_tables_given(tmp_path: Path) -> None:
    path = campaign_spec(tmp_path, file="c.toml", runs=2, scenario="s.csv",
                         tables={"setpoints": {"count": 2}}, variants=[{"name": "x"}])
    assert path == tmp_path / "c.toml"
    assert tomllib.loads(path.read_text()) == {
        "campaign": {"runs": 2, "scenario": "s.csv"}, "setpoints": {"count": 2},
        "variant": [{"name": "x"}]}
