"""The example plants' build script (``fmus/examples/build.py``) for the tests: a script beside
the plants rather than a package module, loaded once per process."""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]

__all__ = ["build", "fmu_name", "problem_file"]


@cache
def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("example_plants",
                                                  ROOT / "fmus" / "examples" / "build.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build(plant: str, folder: Path) -> Path:
    """The FMU of example plant ``plant`` built into ``folder``."""
    return _script().build(plant, folder)


def problem_file(plant: str) -> Path:
    """The control problem of example plant ``plant``."""
    return _script().problem_file(plant)


def fmu_name(plant: str) -> str:
    """The FMU file name of example plant ``plant``."""
    return _script().FMU_NAMES[plant]
