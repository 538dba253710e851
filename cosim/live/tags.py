"""Tags files: the problem's signals as a live plant's control system names them, in its units.

A real plant's OPC UA server names its variables after its own tags (``LIC101.PV``,
``FIC201.SP``), not after the problem's signals, and often keeps them in its own units (a
level in % of span or in mm, a valve in % open). A tags file maps each signal onto a node id
or a browse path, and, in its table form, onto the tag's unit with the keys of a variable map
(:mod:`cosim.core.varmap`)::

    # plant.tags.toml
    root = "2:Plant/2:Area1"        # optional: where relative browse paths start (under
                                    # Objects); default: the folder named for the problem
    [tags]
    h2 = "2:Tanks/2:LT102/2:PV"     # a browse path below root; "2:" is the namespace index
    qa = "/2:Pumps/2:P1/2:Speed"    # a leading "/": a browse path from Objects
    T_in = "Ambient"                # a name without a namespace index matches any namespace

    [tags.h1]                       # the table form: where, and in what unit
    node = "ns=2;s=LIC101.PV"       # a node id (ns=…;s=…, ns=…;i=…, i=…) or a browse path
    unit = "%"                      # the tag's unit (its EngineeringUnits must say the same)
    scale = 50.0                    # plant_value = scale * project_value + offset
    offset = 0.0                    #   (0..2 m is 0..100 %)

A tag whose table gives a ``unit`` but no ``scale`` or ``offset`` is converted by the units
(``unit = "mm"`` for a level the problem has in m: ``scale = 1000``); units that cannot be
related (``%`` and ``m``) need both. A tag without a unit is in the problem's unit. A signal
the file does not name is looked up by its own name below ``root``, which is how ``cosim
serve-plant`` lays out its variables (no tags file needed there); a file that names every
signal by node id needs no ``root``. Faults are one line naming the file and line (exit 2);
a tag the server does not have, or whose EngineeringUnits say another unit, is named with
its signal when the run connects (:mod:`cosim.live.nodes`).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError
from cosim.core.varmap import Affine

__all__ = ["TABLE_KEYS", "Tag", "Tags", "load", "parse_path", "tag_of"]

_NODE_ID = re.compile(r"^(ns=\d+;)?[isgb]=.+$")
_SEGMENT = re.compile(r"^(?:(\d+):)?([^/:]+)$")


#: The keys of a tag's table (``[tags.NAME]``).
TABLE_KEYS = ("node", "unit", "scale", "offset")


@dataclass(frozen=True)
class Tag(Affine):
    """Where one signal lives: a node id, or a browse path of ``(namespace or None, name)``
    segments (``absolute``: from Objects, else below the root); the tag's ``unit``
    (``None``: the problem's) and ``plant_value = scale * project_value + offset``."""

    node_id: str | None = None
    path: tuple[tuple[int | None, str], ...] = ()
    absolute: bool = False
    where: str = ""
    unit: str | None = None
    scale: float = 1.0
    offset: float = 0.0

    def describe(self) -> str:
        """The tag as written (``ns=2;s=LIC101.PV`` or ``2:Tanks/2:LT102``)."""
        if self.node_id is not None:
            return self.node_id
        text = "/".join(f"{ns}:{name}" if ns is not None else name for ns, name in self.path)
        return ("/" if self.absolute else "") + text


@dataclass(frozen=True)
class Tags:
    """A tags file: the root browse path (``None``: the problem's folder) and the tags by
    signal name."""

    root: tuple[tuple[int | None, str], ...] | None = None
    tags: dict[str, Tag] | None = None
    source: str = ""

    def tag(self, signal: str) -> Tag:
        """The signal's tag: the file's, else its own name below the root."""
        given = (self.tags or {}).get(signal)
        return given if given is not None else Tag(path=((None, signal),),
                                                   where="(its own name)")

    def needs_root(self, signals: Sequence[str]) -> bool:
        """Whether one of ``signals`` is found by a browse path below the root."""
        return any(t.node_id is None and not t.absolute for t in map(self.tag, signals))


def parse_path(text: str, where: str) -> tuple[tuple[tuple[int | None, str], ...], bool]:
    """``"2:Tanks/2:LT102"`` as segments, and whether it starts at Objects (a leading ``/``).

    Raises
    ------
    CosimError
        An empty path or segment, a bad namespace index.
    """
    absolute = text.startswith("/")
    body = text[1:] if absolute else text
    segments = []
    for part in body.split("/"):
        m = _SEGMENT.match(part.strip())
        if m is None:
            raise CosimError(f"{where}: browse path {text!r}: segment {part!r} must be NAME "
                             "or NS:NAME (e.g. 2:Tanks/2:LT102)")
        segments.append((int(m.group(1)) if m.group(1) is not None else None, m.group(2)))
    return tuple(segments), absolute


def load(path: str | Path, signals: Sequence[str],
         units: Mapping[str, str] | None = None) -> Tags:
    """Read a tags file for a problem whose signals are ``signals`` (in ``units``, by
    signal: a tag that gives only its unit is converted from them).

    Raises
    ------
    CosimError
        Not found, invalid TOML, an unknown key or signal, a tag that is neither a string
        nor a table, a malformed node id or browse path, a bad scale, offset or unit
        (``file:line``).
    """
    p = Path(path)
    if not p.is_file():
        raise CosimError(f"{p}: tags file not found")
    text = p.read_text(encoding="utf-8", errors="replace")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"at line (\d+)", str(exc))
        line = int(m.group(1)) if m else 1
        raise CosimError(f"{p}:{line}: invalid TOML: {str(exc).split(' (at')[0]}") from None

    def where(*keys: str) -> str:
        return f"{p}:{next((n for n in (_line(text, k) for k in keys) if n), 1)}"

    unknown = [k for k in doc if k not in ("root", "tags")]
    if unknown:
        raise CosimError(f"{where(unknown[0])}: unknown key '{unknown[0]}' (known: root, "
                         "[tags])")
    root = None
    if "root" in doc:
        if not isinstance(doc["root"], str) or not doc["root"].strip():
            raise CosimError(f"{where('root')}: 'root' must be a browse path string")
        root, _ = parse_path(doc["root"].strip().lstrip("/"), where("root"))
    table = doc.get("tags", {})
    if not isinstance(table, dict):
        raise CosimError(f"{where('tags')}: 'tags' must be a table ([tags])")
    tags = {}
    for signal, value in table.items():
        at = where(f"tags.{signal}", signal)
        if signal not in signals:
            raise CosimError(f"{at}: '{signal}' is not a signal of the problem (its signals: "
                             f"{', '.join(signals)})")
        tag = tag_of(signal, value, at)
        tags[signal] = _converted(tag, signal, (units or {}).get(signal), value, at)
    return Tags(root=root, tags=tags, source=str(p))


def tag_of(signal: str, value: Any, at: str) -> Tag:
    """One tag of ``signal``, located ``at``: a string (where), or a table (where, unit,
    scale, offset).

    Raises
    ------
    CosimError
        Not a string or a table, a malformed node id or browse path, an unknown key, a bad
        unit, scale or offset.
    """
    entry = value if isinstance(value, dict) else {"node": value}
    bad = [k for k in entry if k not in TABLE_KEYS]
    if bad:
        raise CosimError(f"{at}: [tags.{signal}]: unknown key '{bad[0]}' (known: "
                         f"{', '.join(TABLE_KEYS)})")
    node = entry.get("node")
    if not isinstance(node, str) or not node.strip():
        raise CosimError(f"{at}: the tag of '{signal}' must be a node id (\"ns=2;s=...\") "
                         "or a browse path (\"2:Folder/2:Name\") string"
                         + (" (its table's 'node')" if isinstance(value, dict) else ""))
    node = node.strip()
    if _NODE_ID.match(node):
        tag = Tag(node_id=node, where=at)
    elif "=" in node.split("/")[0]:
        raise CosimError(f"{at}: node id {node!r}: expected ns=<index>;<i|s|g|b>=<id> "
                         "or i=<number>")
    else:
        segments, absolute = parse_path(node, at)
        tag = Tag(path=segments, absolute=absolute, where=at)
    unit = entry.get("unit")
    if unit is not None and (not isinstance(unit, str) or not unit.strip()):
        raise CosimError(f"{at}: [tags.{signal}] 'unit' must be a unit string (\"%\", "
                         "\"mm\", \"m3/s\")")
    numbers = {}
    for key in ("scale", "offset"):
        v = entry.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)
                              or not math.isfinite(v) or (key == "scale" and v == 0)):
            what = "a finite number other than 0" if key == "scale" else "a finite number"
            raise CosimError(f"{at}: [tags.{signal}] '{key}' must be {what}, got {v!r}")
        if v is not None:
            numbers[key] = float(v)
    return replace(tag, unit=unit.strip() if unit else None, **numbers)


def _converted(tag: Tag, signal: str, problem_unit: str | None, value: Any, at: str) -> Tag:
    """``tag`` with the scale and offset its unit implies, when it gives a unit and neither
    a scale nor an offset (a variable map's rule: :mod:`cosim.core.varmap`)."""
    if (tag.unit is None or problem_unit is None or not isinstance(value, dict)
            or "scale" in value or "offset" in value):
        return tag
    from cosim.core.binding import UnitError, unit_conversion

    try:
        conv = unit_conversion(problem_unit, tag.unit)
    except UnitError as exc:
        raise CosimError(f"{at}: [tags.{signal}]: the tag's unit '{tag.unit}' cannot be "
                         f"converted from the problem's '{problem_unit}' ({exc}): give its "
                         "'scale' and 'offset' (plant_value = scale * project_value + "
                         "offset)") from None
    return replace(tag, scale=conv.scale, offset=conv.offset)


def _line(text: str, key: str) -> int:
    """The line where ``key`` is assigned or opens a table (0 when not found)."""
    pattern = re.compile(rf"^\s*(\[\s*{re.escape(key)}\s*\]|\"?{re.escape(key)}\"?\s*=)")
    for number, line in enumerate(text.splitlines(), start=1):
        if pattern.match(line):
            return number
    return 0
