"""Griffe extension for the API reference: Sphinx roles in docstrings as code spans.

The docstrings are numpydoc and use Sphinx cross-reference roles (``:class:`~cosim.x.Y```,
``:func:``, ``:mod:``, ``:data:``, ``:meth:``, ``:attr:``, ``:exc:``) and reST literal-block
markers (``Format::``). mkdocstrings renders Markdown, where a role would show as the role
name followed by a code span; this extension rewrites each role into a plain code span (the
last component only when the target starts with ``~``, as in Sphinx) and ``::`` at the end of
a line into ``:`` before the docstrings are parsed. The source files are not changed.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|mod|data|meth|attr|exc|obj|const):`(~?)([^`]+)`")
_LITERAL = re.compile(r"(\S)::[ \t]*$", re.MULTILINE)


def _role(match: re.Match[str]) -> str:
    short, target = match.group(1), match.group(2)
    if short:
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


def rewrite(text: str) -> str:
    """``text`` with Sphinx roles as code spans and ``::`` literal markers as ``:``."""
    return _LITERAL.sub(r"\1:", _ROLE.sub(_role, text))


class SphinxRoles(griffe.Extension):
    """Rewrite every docstring once, when its object is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rewrite(obj.docstring.value)
