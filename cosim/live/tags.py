"""Tags files: the problem's signals as a live plant's control system names them.

A real plant's OPC UA server names its variables after its own tags (``LIC101.PV``,
``FIC201.SP``), not after the problem's signals. A tags file maps each signal onto a node id
or a browse path::

    # plant.tags.toml
    root = "2:Plant/2:Area1"        # optional: where relative browse paths start (under
                                    # Objects); default: the folder named for the problem
    [tags]
    h1 = "ns=2;s=LIC101.PV"         # a node id (ns=…;s=…, ns=…;i=…, i=…)
    h2 = "2:Tanks/2:LT102/2:PV"     # a browse path below root; "2:" is the namespace index
    qa = "/2:Pumps/2:P1/2:Speed"    # a leading "/": a browse path from Objects
    T_in = "Ambient"                # a name without a namespace index matches any namespace

A signal the file does not name is looked up by its own name below ``root``, which is how
``cosim serve-plant`` lays out its variables (no tags file needed there). Faults are one line
naming the file and line (exit 2); a tag the server does not have is named with its signal
when the run connects (:mod:`cosim.live.session`).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from cosim.core.errors import CosimError

__all__ = ["Tag", "Tags", "load", "parse_path"]

_NODE_ID = re.compile(r"^(ns=\d+;)?[isgb]=.+$")
_SEGMENT = re.compile(r"^(?:(\d+):)?([^/:]+)$")


@dataclass(frozen=True)
class Tag:
    """Where one signal lives: a node id, or a browse path of ``(namespace or None, name)``
    segments (``absolute``: from Objects, else below the root)."""

    node_id: str | None = None
    path: tuple[tuple[int | None, str], ...] = ()
    absolute: bool = False
    where: str = ""

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


def load(path: str | Path, signals: list[str] | tuple[str, ...]) -> Tags:
    """Read a tags file for a problem whose signals are ``signals``.

    Raises
    ------
    CosimError
        Not found, invalid TOML, an unknown key or signal, a value that is not a string, a
        malformed node id or browse path (``file:line``).
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

    def where(key: str) -> str:
        return f"{p}:{_line(text, key)}"

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
        at = where(signal)
        if signal not in signals:
            raise CosimError(f"{at}: '{signal}' is not a signal of the problem (its signals: "
                             f"{', '.join(signals)})")
        if not isinstance(value, str) or not value.strip():
            raise CosimError(f"{at}: the tag of '{signal}' must be a node id (\"ns=2;s=...\") "
                             "or a browse path (\"2:Folder/2:Name\") string")
        value = value.strip()
        if _NODE_ID.match(value):
            tags[signal] = Tag(node_id=value, where=at)
        elif "=" in value.split("/")[0]:
            raise CosimError(f"{at}: node id {value!r}: expected ns=<index>;<i|s|g|b>=<id> "
                             "or i=<number>")
        else:
            segments, absolute = parse_path(value, at)
            tags[signal] = Tag(path=segments, absolute=absolute, where=at)
    return Tags(root=root, tags=tags, source=str(p))


def _line(text: str, key: str) -> int:
    """The line where ``key`` is assigned or opens a table (1 when not found)."""
    pattern = re.compile(rf"^\s*(\[\s*{re.escape(key)}\s*\]|\"?{re.escape(key)}\"?\s*=)")
    for number, line in enumerate(text.splitlines(), start=1):
        if pattern.match(line):
            return number
    return 1
