"""Controller registry: names and module:Class strings."""

from __future__ import annotations

import sys

import pytest

from cosim.adapters.pi import PIController
from cosim.core.errors import CosimError
from cosim.core.registry import CONTROLLERS, DEFAULT, create, resolve


def test_names_and_specs() -> None:
    assert DEFAULT == "robust-mpc" and CONTROLLERS["pi"] == "cosim.adapters.pi:PIController"
    assert resolve("pi") is PIController
    assert resolve("cosim.adapters.pi:PIController") is PIController
    assert isinstance(create("pi"), PIController)


@pytest.mark.parametrize(("name", "words"), [
    ("nope", "unknown controller 'nope'"),
    ("no_such_module:X", "cannot import module 'no_such_module'"),
    ("cosim.adapters.pi:Nothing", "is not a Component class"),
    ("cosim.adapters.pi:PILoop", "is not a Component class"),
])
def test_errors(name: str, words: str) -> None:
    with pytest.raises(CosimError, match=words):
        resolve(name)


def test_options_are_parsed_as_json_or_text() -> None:
    from cosim.core.registry import parse_options

    assert parse_options(["a=0.02", "b=true", "c=[1, 2]", "model=my.json", "e="]) == {
        "a": 0.02, "b": True, "c": [1, 2], "model": "my.json", "e": ""}
    with pytest.raises(CosimError, match="expected KEY=VALUE"):
        parse_options(["novalue"])
    # a controller FMU's parameter of a family: identifiers joined by dots
    assert parse_options(["R.qa=0.05", "offset_weight.h_1=1e3"]) == {
        "R.qa": 0.05, "offset_weight.h_1": 1e3}
    for bad in ("R.=1", ".qa=1", "R..qa=1", "1R=1", "R qa=1"):
        with pytest.raises(CosimError, match="expected KEY=VALUE"):
            parse_options([bad])


def test_create_passes_options_and_names_unknown_ones() -> None:
    ctrl = create("pi", {"pairing": "diagonal"})
    assert [(loop.y, loop.u) for loop in ctrl.loops] == [("h1", "qa"), ("h2", "qb")]
    with pytest.raises(CosimError, match="controller 'pi' has no option 'gain'"):
        create("pi", {"gain": 2.0})
    with pytest.raises(CosimError, match="problem=1: expected the path of a problem file"):
        create("pi", {"problem": 1})
    with pytest.raises(CosimError, match="controller 'pi': unknown pairing 'sideways'"):
        create("pi", {"pairing": "sideways"})


def test_constructor_errors_are_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    import types

    from cosim.adapters.pi import PIController

    class Fails(PIController):
        def __init__(self) -> None:
            raise RuntimeError("first line\nsecond line:\n  third")

    module = types.ModuleType("cosim_test_fails")
    module.Fails = Fails
    monkeypatch.setitem(sys.modules, "cosim_test_fails", module)
    with pytest.raises(CosimError) as info:
        create("cosim_test_fails:Fails")
    assert str(info.value) == ("controller 'cosim_test_fails:Fails': cannot create Fails: "
                               "RuntimeError: first line second line: third")
