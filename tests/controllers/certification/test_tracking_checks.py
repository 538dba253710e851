"""The tracking law's (H5): whether the admissible steady outputs ``{y : L y ≤ rhs}`` have a
point, for every right-hand side a certificate can give, infinite or undefined rows
included (a library's error never reaches the user)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.laws.tracking.checks import _ys_nonempty

#: The box 0 ≤ y_1, y_2 ≤ 1 as rows of L y ≤ rhs.
L = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])


@pytest.mark.parametrize(("rhs", "nonempty"), [
    ([1.0, 1.0, 0.0, 0.0], True),
    ([1.0, 1.0, -2.0, 0.0], False),               # 2 <= y_1 <= 1
    ([np.inf, 1.0, 0.0, 0.0], True),              # a row loosened past any bound
    ([np.inf] * 4, True),                         # no row left: the whole space
    ([1.0, -np.inf, 0.0, 0.0], False),            # a row tightened past any bound
    ([1.0, np.nan, 0.0, 0.0], False),             # an undefined tightening (0 · inf)
])
def test_the_admissible_set_with_infinite_and_undefined_rows(rhs: list, nonempty: bool) -> None:
    ok, centre = _ys_nonempty(L, np.array(rhs))
    assert ok is nonempty
    if ok:
        assert centre is not None and np.all(L @ centre <= np.array(rhs) + 1e-9)
    else:
        assert centre is None
