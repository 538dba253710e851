"""A campaign spec's TOML text: the ``file:line`` of its keys and the checks of their values.

tomllib gives no positions, so :class:`Locator` finds a key's line in the text itself (a
``[table]`` key, the ``nth`` ``[[table]]``'s, or the header), and every check here fails with
a :class:`~cosim.core.errors.CosimError` ``file:line: message`` naming it (exit 2): a number
out of its range (:func:`number`), a file that does not exist beside the spec or in the
current folder (:func:`file`, found by :func:`resolve`). :mod:`cosim.campaign.spec` reads the
tables with them; :mod:`cosim.campaign.plan` locates the draws a plant does not know.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["Locator", "file", "finite", "number", "resolve"]


class Locator:
    """``file:line`` of keys in a TOML text (tomllib gives no positions)."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()

    def line(self, table: str | None, key: str | None = None, nth: int = 0) -> int:
        """Line of ``key`` in ``[table]`` (the ``nth`` ``[[table]]``), or of the header."""
        current, count, header = None, -1, 0
        for i, raw in enumerate(self.lines, start=1):
            s = raw.strip()
            m = re.match(r"^\[\[\s*([^\]]+?)\s*\]\]", s) or re.match(r"^\[\s*([^\]]+?)\s*\]", s)
            if m:
                current = m.group(1).replace('"', "").replace(" ", "")
                if current == table:
                    count += 1
                    if count == nth:
                        header = i
                continue
            if key is None or current != table or count != nth:
                continue
            k = re.match(r'^("([^"]*)"|([A-Za-z0-9_.-]+))\s*=', s)
            if k and (k.group(2) if k.group(2) is not None else k.group(3)) == key:
                return i
        if table is None and key is not None:
            k = re.escape(key)
            for i, raw in enumerate(self.lines, start=1):
                if re.match(rf'^\s*("?{k}"?\s*=|\[\[?\s*"?{k}"?\s*[\].])', raw):
                    return i
        return header or 1

    def error(self, message: str, table: str | None, key: str | None = None,
              nth: int = 0) -> CosimError:
        """The error ``file:line: message`` at ``key`` of ``[table]`` (see :meth:`line`)."""
        return CosimError(f"{self.path}:{self.line(table, key, nth)}: {message}")


def resolve(raw: str, base: Path) -> Path:
    """The path ``raw`` names: beside the spec (in ``base``) when it is there or not in the
    current folder either, else in the current folder."""
    path = Path(raw).expanduser()
    if path.is_absolute():
        return path
    beside = base / path
    return beside if beside.exists() or not path.exists() else path


def finite(value: Any) -> bool:
    """Whether ``value`` is a finite TOML number (not a boolean)."""
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def number(value: Any, loc: Locator, table: str, key: str, *, low: float | None = None,
           integer: bool = False, positive: bool = False) -> float:
    """``value`` of ``key`` checked: a finite number (an integer), ``>= low``, ``> 0``."""
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if ok and integer:
        ok = isinstance(value, int)
    if ok and not math.isfinite(value):
        ok = False
    if ok and low is not None and value < low:
        ok = False
    if ok and positive and value <= 0:
        ok = False
    if not ok:
        what = "an integer" if integer else "a number"
        if positive:
            what = f"a positive {what.split()[-1]}"
        elif low is not None:
            what = f"{what} >= {low:g}"
        raise loc.error(f"{key} = {value!r}: expected {what}", table, key)
    return value


def file(value: Any, loc: Locator, table: str, key: str, kind: str) -> Path:
    """The existing file (a ``kind``) that ``key`` names (see :func:`resolve`)."""
    if not isinstance(value, str) or not value:
        raise loc.error(f"{key}: expected the path of the {kind} as a string", table, key)
    path = resolve(value, loc.path.parent)
    if not path.is_file():
        raise loc.error(f"{key} = {value!r}: {kind} not found (looked beside the spec, "
                        f"{loc.path.parent}, and in the current folder)", table, key)
    return path
