"""TOML text of the tests' files (control problems, campaign specs) written from Python values:
one writer for the tables the tests would otherwise type out again and again.

>>> print(toml_text({"campaign": {"runs": 2, "controller": "pi"},
...                  "draw": {"plant.a1": {"uniform": [1.2e-4, 1.4e-4]}},
...                  "variant": [{"name": "a"}]}), end="")
[campaign]
runs = 2
controller = "pi"
<BLANKLINE>
[draw]
"plant.a1" = { uniform = [0.00012, 0.00014] }
<BLANKLINE>
[[variant]]
name = "a"
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["campaign_spec", "toml_text", "toml_value"]


def _key(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)


def toml_value(value: Any) -> str:
    """``value`` as a TOML value: a mapping as an inline table, a path as its POSIX string."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, Path):
        value = value.as_posix()
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return repr(value)


def _is_tables(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, Mapping)
                                                            for v in value)


def _lines(items: Mapping[str, Any]) -> str:
    return "".join(f"{_key(k)} = {toml_value(v)}\n" for k, v in items.items())


def toml_text(doc: Mapping[str, Any]) -> str:
    """``doc`` as TOML: its plain values first, then each mapping as a table (a key with dots,
    ``"inputs.P"``, names the table ``[inputs.P]``) and each list of mappings as an array of
    tables (``[[variant]]``); the values inside a table are written inline, blank lines
    between the tables."""
    plain = {k: v for k, v in doc.items() if not isinstance(v, Mapping) and not _is_tables(v)}
    parts = [_lines(plain)] if plain else []
    for name, value in doc.items():
        if isinstance(value, Mapping):
            parts.append(f"[{name}]\n" + _lines(value))
        elif _is_tables(value):
            parts += [f"[[{name}]]\n" + _lines(table) for table in value]
    return "\n".join(parts)


def campaign_spec(folder: Path, *, file: str = "spec.toml", options: Mapping | None = None,
                  draw: Mapping | None = None, tables: Mapping[str, Mapping] | None = None,
                  variants: list[Mapping] | tuple = (), **campaign: Any) -> Path:
    """``folder/file``: a campaign spec of the ``[campaign]`` keys ``campaign``, then its
    ``[controller.options]``, ``[draw]`` (a column's distribution as a mapping, such as
    ``{"uniform": [lo, hi]}``), the other ``tables`` (``{"setpoints": {...}}``) and the
    ``[[variant]]`` tables, where given."""
    doc: dict[str, Any] = {"campaign": campaign, "controller.options": options, "draw": draw,
                           **(tables or {}), "variant": list(variants)}
    path = folder / file
    path.write_text(toml_text({k: v for k, v in doc.items() if v}))
    return path
