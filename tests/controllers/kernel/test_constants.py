"""The numbers of a generated C source as a data file (:mod:`controllers.kernel.constants`):
the layout's key, the file's bytes (ranges, checksum, values), and the values it refuses.
What ``loader.c`` refuses when it reads one: ``tests/cosim/adapters/test_controller_export.py``
(a damaged or edited ``controller.dat``)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from controllers.kernel.constants import HEADER, INT_RANGE, MAGIC, PLAUSIBLE, Constants, checksum


def _constants(n: int) -> Constants:
    c = Constants()
    c.array("W", np.arange(n, dtype=float).reshape(1, n))
    c.array("H", [1.0, np.inf], finite=False)
    c.array("P", [2, -1], "int")
    c.scalar("S", 0.5, limits=(0.0, 1.0))
    c.scalar("K", 3, "int")
    return c


def test_the_data_file_is_the_ranges_then_the_values_in_declaration_order() -> None:
    c = _constants(3)
    data = c.data()
    assert data[:8] == MAGIC and data[8:24] == c.key().encode()
    count, crc = struct.unpack("<QQ", data[24:HEADER])
    assert count == c.count() == 3 + 2 + 2 + 1 + 1
    assert crc == zlib.crc32(data[HEADER:]) == checksum(data[HEADER:])
    ranges = np.frombuffer(data[HEADER:HEADER + 5 * 24], "<f8").reshape(5, 3)
    np.testing.assert_array_equal(ranges, [[-PLAUSIBLE, PLAUSIBLE, 0], [-PLAUSIBLE, PLAUSIBLE, 1],
                                           [*INT_RANGE, 0], [0, 1, 0], [*INT_RANGE, 0]])
    values = np.frombuffer(data[HEADER + 5 * 24:], "<f8")
    np.testing.assert_array_equal(values, [0, 1, 2, 1, np.inf, 2, -1, 0.5, 3])
    assert "static double W[3];" in c.declarations() and "static int K;" in c.declarations()
    assert '{"K", &K, 1, 1}' in c.table() and '{"W", W, 3, 0}' in c.table()


def test_the_key_is_the_layout_not_the_values() -> None:
    a, b = _constants(3), _constants(3)
    b.array("Z", [])
    assert _constants(3).key() == a.key() != _constants(4).key()
    assert b.key() != a.key() and b.count() == a.count() + 1   # an empty array: one entry
    other = Constants()
    for item in a:
        other.array(item.name, item.values * 2 if item.ctype == "double" else item.values,
                    item.ctype, finite=False)
    assert other.key() != a.key()   # scalars and arrays are different layouts


@pytest.mark.parametrize(("add", "message"), [
    (lambda c: c.array("A", [1.0, np.nan], finite=False), "non-finite entries in A"),
    (lambda c: c.array("A", [np.inf]), "non-finite entries in A"),
    (lambda c: c.array("A", [1.5], "int"), "A: entries are not C ints"),
    (lambda c: c.array("A", [2.0**31], "int"), "A: entries are not C ints"),
    (lambda c: c.array("S", [1.0]), "constant S defined twice"),
    (lambda c: c.array("A", [1.0], "float"), "C type 'float'"),
    (lambda c: c.array("A", [1e300]), r"A: 1e\+300 is outside its plausible range"),
    (lambda c: c.array("A", [-2.0], "int"), r"A: -2.0 is outside its plausible range \[-1, "),
    (lambda c: c.scalar("A", 1.5, limits=(0.0, 1.0)), r"outside its plausible range \[0, 1\]"),
    (lambda c: c.scalar("A", 0.5, limits=(1.0, 0.0)), "A: empty range")])
def test_what_cannot_be_a_constant_is_refused(add, message: str) -> None:
    c = Constants()
    c.scalar("S", 1.0)
    with pytest.raises(ValueError, match=message):
        add(c)
