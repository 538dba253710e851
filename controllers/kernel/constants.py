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

Each constant has a plausible range (:data:`PLAUSIBLE` unless its definition narrows it, and
whether ``±inf`` may stand for "unbounded"): a value outside it is refused where the file is
written and where it is read, so that a damaged or edited file is never run.

The data file, little endian: the magic ``GKDATA02`` (8 bytes), the layout key
(:meth:`Constants.key`: 16 ASCII hex digits of the names, types and sizes, so that a file is
never read into another layout), the number of values (uint64), the checksum of everything
after the header (uint64: its CRC-32, :func:`checksum`, which changes with any changed byte),
then per constant its range (float64 low, high, and 1.0 where ``±inf`` is allowed, else
0.0), then the values (float64; integers exact), both in declaration order.
"""

from __future__ import annotations

import hashlib
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

__all__ = ["HEADER", "INT_RANGE", "MAGIC", "PLAUSIBLE", "Constant", "Constants", "checksum"]

#: The first bytes of a data file (``loader.c`` GK_DATA_MAGIC).
MAGIC = b"GKDATA02"
#: Bytes before the ranges: magic, key, number of values, checksum (``loader.c``
#: GK_DATA_HEADER).
HEADER = 40
#: Largest integer a constant of C type ``int`` may hold.
_INT_MAX = 2**31 - 1
#: The plausible magnitude of a ``double`` constant whose definition gives no range: far
#: beyond any weight, box, gain or tolerance a design holds, short of an absurd value.
PLAUSIBLE = 1e15
#: The plausible range of an ``int`` constant whose definition gives no range (indices, with
#: -1 for none; counts; flags).
INT_RANGE = (-1, 10_000_000)


def checksum(data: bytes) -> int:
    """The CRC-32 of ``data`` (zlib's, ``loader.c`` gk_crc32): it detects any changed byte,
    and any burst of changed bits up to 32 long."""
    return zlib.crc32(data)


@dataclass(frozen=True)
class Constant:
    """One named constant: its values (flattened), C type, whether it is a scalar, and its
    plausible range ``[low, high]`` (``infinite``: ``±inf`` allowed too)."""

    name: str
    values: np.ndarray
    ctype: str
    scalar: bool
    low: float = -PLAUSIBLE
    high: float = PLAUSIBLE
    infinite: bool = False

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

    def _add(self, name: str, values: object, ctype: str, scalar: bool, finite: bool,
             limits: tuple[float, float] | None) -> None:
        if ctype not in ("double", "int"):
            raise ValueError(f"{name}: C type {ctype!r} is not double or int")
        if any(c.name == name for c in self._items):
            raise ValueError(f"constant {name} defined twice")
        a = np.ascontiguousarray(np.asarray(values, dtype=float)).ravel()
        if np.any(np.isnan(a)) or (finite and not np.all(np.isfinite(a))):
            raise ValueError(f"non-finite entries in {name}")
        if ctype == "int" and not (np.all(a == np.round(a)) and np.all(np.abs(a) <= _INT_MAX)):
            raise ValueError(f"{name}: entries are not C ints")
        low, high = limits if limits is not None else (
            INT_RANGE if ctype == "int" else (-PLAUSIBLE, PLAUSIBLE))
        if not low <= high:
            raise ValueError(f"{name}: empty range [{low!r}, {high!r}]")
        beyond = np.isfinite(a) & ((a < low) | (a > high))
        if np.any(beyond):
            raise ValueError(f"{name}: {float(a[beyond][0])!r} is outside its plausible range "
                             f"[{low:g}, {high:g}]")
        self._items.append(Constant(name, a, ctype, scalar, float(low), float(high),
                                    not finite))

    def array(self, name: str, values: object, ctype: str = "double", finite: bool = True,
              limits: tuple[float, float] | None = None) -> None:
        """Add the array ``name`` (``finite=False``: ±inf allowed; NaN never is), its
        finite values inside ``limits`` (default: ``±PLAUSIBLE``; an int's :data:`INT_RANGE`)."""
        self._add(name, values, ctype, False, finite, limits)

    def scalar(self, name: str, value: float, ctype: str = "double",
               limits: tuple[float, float] | None = None) -> None:
        """Add the scalar ``name`` (inside ``limits``, as :meth:`array`)."""
        self._add(name, [value], ctype, True, True, limits)

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
        """The data file of these values (module docstring)."""
        values = np.concatenate([c.values if c.values.size else np.zeros(1)
                                 for c in self._items]) if self._items else np.zeros(0)
        ranges = np.array([(c.low, c.high, float(c.infinite)) for c in self._items],
                          dtype=float).reshape(-1)
        body = ranges.astype("<f8").tobytes() + values.astype("<f8").tobytes()
        return (MAGIC + self.key().encode() + struct.pack("<QQ", values.size, checksum(body))
                + body)
