"""Controller registry: names and module:Class strings."""

from __future__ import annotations

import pytest

from controllers.pi import PIController
from cosim.errors import CosimError
from cosim.registry import CONTROLLERS, DEFAULT, create, resolve


def test_names_and_specs() -> None:
    assert DEFAULT == "robust-mpc" and CONTROLLERS["pi"] == "controllers.pi:PIController"
    assert resolve("pi") is PIController
    assert resolve("controllers.pi:PIController") is PIController
    assert isinstance(create("pi"), PIController)


@pytest.mark.parametrize(("name", "words"), [
    ("nope", "unknown controller 'nope'"),
    ("no_such_module:X", "cannot import module 'no_such_module'"),
    ("controllers.pi:Nothing", "is not a Component class"),
    ("controllers.pi:PILoop", "is not a Component class"),
])
def test_errors(name: str, words: str) -> None:
    with pytest.raises(CosimError, match=words):
        resolve(name)
