"""Tags files: node ids and browse paths parsed, the table form's units and scales, every fault
one line naming file and line; units as servers write them (:mod:`cosim.live.nodes`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.core.errors import CosimError
from cosim.live import nodes, tags

SIGNALS = ["qa", "qb", "h1", "h2"]
UNITS = {"qa": "m3/s", "qb": "m3/s", "h1": "m", "h2": "m"}


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
    ('[tags]\nh2 = "x"\n[tags.h1]\nnode = "a"\nspan = 2\n', 3,
     "[tags.h1]: unknown key 'span' (known: node, unit, scale, offset)"),
    ('[tags]\nh1 = { unit = "%" }\n', 2, "(its table's 'node')"),
    ('[tags.h1]\nnode = "a"\nunit = "%"\n', 1,
     "the tag's unit '%' cannot be converted from the problem's 'm'"),
    ('[tags.h1]\nnode = "a"\nscale = 0\n', 1, "'scale' must be a finite number other than 0"),
    ('[tags.qa]\nnode = "a"\nunit = 3\n', 1, "'unit' must be a unit string"),
])
def test_faults_name_file_and_line(tmp_path: Path, text: str, line: int, words: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(CosimError) as err:
        tags.load(path, SIGNALS, UNITS)
    assert str(err.value).startswith(f"{path}:{line}:") and words in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match="tags file not found"):
        tags.load(tmp_path / "none.toml", SIGNALS)


def test_table_form_units_and_scales(tmp_path: Path) -> None:
    """A tag's table gives its unit and scale (plant = scale * project + offset); a unit
    alone is converted from the problem's; the string form stays in the problem's unit."""
    t = tags.load(write(tmp_path, '[tags]\nqa = "ns=3;s=P101.OUT"\n'
                                  'h2 = { node = "3:Levels/3:LT102", unit = "mm" }\n'
                                  '[tags.h1]\nnode = "ns=3;s=LT101.PV"\nunit = "%"\n'
                                  'scale = 50.0\noffset = -10\n'), SIGNALS, UNITS)
    h1, h2, qa = t.tag("h1"), t.tag("h2"), t.tag("qa")
    assert (h1.node_id, h1.unit, h1.to_plant(2.0), h1.from_plant(40.0)) == (
        "ns=3;s=LT101.PV", "%", 90.0, 1.0)
    assert h2.path == ((3, "Levels"), (3, "LT102")) and (h2.unit, h2.scale) == ("mm", 1000.0)
    assert (qa.unit, qa.scale, qa.offset) == (None, 1.0, 0.0)
    assert h1.where.endswith(":4") and h2.where.endswith(":3")
    assert not t.needs_root(["h1", "qa"]) and t.needs_root(["h2"])


@pytest.mark.parametrize(("server", "problem", "same"), [
    ("m³/s", "m3/s", True), ("m", "m", True), ("L/min", "l/min", True), ("mm", "m", False),
    ("%", "m", False), ("°C", "degC", True), ("degC", "K", False), ("bogus", "m", False)])
def test_units_as_servers_write_them(server: str, problem: str, same: bool) -> None:
    assert nodes.same_unit(server, problem) is same


def test_engineering_units_by_display_name_or_unece_code() -> None:
    """OPC UA Part 8's EUInformation: the display name when there is one, else the UNECE
    code (UnitId: its letters as a big-endian integer)."""
    from asyncua import ua

    def eu(code: str, text: str = "") -> object:
        return ua.EUInformation(UnitId=int.from_bytes(code.encode(), "big"),
                                DisplayName=ua.LocalizedText(text))

    assert nodes.server_unit(eu("MMT", "mm")) == "mm" and nodes.server_unit(eu("P1")) == "%"
    assert nodes.server_unit(eu("MQS")) == "m3/s" and nodes.server_unit(eu("ZZZ")) == "UNECE ZZZ"
    assert nodes.server_unit(ua.EUInformation(UnitId=-1)) is None
