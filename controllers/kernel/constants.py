"""The numbers a generated C source carries (weights, bounds, gains, tolerances), as data
loaded at run time.

The source declares them only (:meth:`Constants.declarations`), with a table of their names,
addresses and sizes (:meth:`Constants.table`); the values come from a data file
(:meth:`Constants.data`) that ``loader.c`` reads at load time. That source is the same for
every problem of the same dimensions, so one binary serves many models: the FHOCP kernel
(:mod:`controllers.kernel.compiled_kernel`) compiles once per dimensions, and the exported
controller (:mod:`controllers.kernel.controller_source`), compiled from the same source,
carries its model, weights and certificate as a file in the controller FMU's
``resources/``.

The data file: the magic ``GKDATA01`` (8 bytes), the layout key (:meth:`Constants.key`: 16
ASCII hex digits of the names, types and sizes, so that a file is never read into another
layout), the number of values (uint64) and the values (float64; integers exact), little
endian, in declaration order.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

__all__ = ["MAGIC", "Constant", "Constants"]

#: The first bytes of a data file (``loader.c`` GK_DATA_MAGIC).
MAGIC = b"GKDATA01"
#: Largest integer a constant of C type ``int`` may hold.
_INT_MAX = 2**31 - 1


@dataclass(frozen=True)
class Constant:
    """One named constant: its values (flattened), C type and whether it is a scalar."""

    name: str
    values: np.ndarray
    ctype: str
    scalar: bool

    @property
    def size(self) -> int:
        """The C array's length (an empty array is declared with one element)."""
        return 1 if self.scalar else max(self.values.size, 1)


class Constants:
    """An ordered collection of named constants (:meth:`array`, :meth:`scalar`)."""

    def __init__(self) -> None:
        self._items: list[Constant] = []

    def __iter__(self) -> Iterator[Constant]:
        return iter(self._items)

    def __add__(self, other: Constants) -> Constants:
        out = Constants()
        out._items = [*self._items, *other._items]
        return out

    def _add(self, name: str, values: object, ctype: str, scalar: bool, finite: bool) -> None:
        if ctype not in ("double", "int"):
            raise ValueError(f"{name}: C type {ctype!r} is not double or int")
        if any(c.name == name for c in self._items):
            raise ValueError(f"constant {name} defined twice")
        a = np.ascontiguousarray(np.asarray(values, dtype=float)).ravel()
        if np.any(np.isnan(a)) or (finite and not np.all(np.isfinite(a))):
            raise ValueError(f"non-finite entries in {name}")
        if ctype == "int" and not (np.all(a == np.round(a)) and np.all(np.abs(a) <= _INT_MAX)):
            raise ValueError(f"{name}: entries are not C ints")
        self._items.append(Constant(name, a, ctype, scalar))

    def array(self, name: str, values: object, ctype: str = "double",
              finite: bool = True) -> None:
        """Add the array ``name`` (``finite=False``: ±inf allowed; NaN never is)."""
        self._add(name, values, ctype, False, finite)

    def scalar(self, name: str, value: float, ctype: str = "double") -> None:
        """Add the scalar ``name``."""
        self._add(name, [value], ctype, True, True)

    def declarations(self) -> str:
        """The definitions without values (filled by ``loader.c`` from a data file)."""
        return "".join(f"static {c.ctype} {c.name}{'' if c.scalar else f'[{c.size}]'};\n"
                       for c in self._items)

    def key(self) -> str:
        """The layout key: a hash of the names, types and sizes, in order."""
        text = ";".join(f"{c.name}:{c.ctype}:{c.size}:{int(c.scalar)}" for c in self._items)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def count(self) -> int:
        """The number of values in a data file."""
        return sum(c.size for c in self._items)

    def table(self) -> str:
        """The table ``loader.c`` fills the declarations from, with ``GK_DATA_KEY``,
        ``GK_DATA_COUNT`` (entries) and ``GK_DATA_VALUES`` (values)."""
        rows = ",\n".join(
            f'  {{"{c.name}", {"&" if c.scalar else ""}{c.name}, {c.size}, '
            f'{int(c.ctype == "int")}}}' for c in self._items)
        return ("typedef struct gk_datum { const char *name; void *at; long size; int is_int; }"
                " gk_datum;\n"
                f'#define GK_DATA_KEY "{self.key()}"\n'
                f"#define GK_DATA_COUNT {len(self._items)}\n"
                f"#define GK_DATA_VALUES {self.count()}\n"
                "static const gk_datum GK_DATA[GK_DATA_COUNT] = {\n" + rows + "};\n")

    def data(self) -> bytes:
        """The data file of these values."""
        values = np.concatenate([c.values if c.values.size else np.zeros(1)
                                 for c in self._items]) if self._items else np.zeros(0)
        return (MAGIC + self.key().encode() + struct.pack("<Q", values.size)
                + values.astype("<f8").tobytes())
