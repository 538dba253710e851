"""Regression suite fixtures: the plant FMUs, and every shipped case run once, in parallel.

References in ``scenarios/references/`` are written ONLY with::

    .venv/bin/pytest tests/regression --update-references

A normal run never writes them.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.regression import regression_cases as rc

HERE = Path(__file__).parent


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--update-references", action="store_true", default=False,
        help="regression suite: overwrite scenarios/references/*.csv with the results of "
             "this run (do it deliberately, then review and commit the diff)")


@pytest.fixture(scope="session")
def update_references(request: pytest.FixtureRequest) -> bool:
    return bool(request.config.getoption("--update-references"))


@pytest.fixture(scope="session")
def thirdparty_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The third-party example plant, built by pythonfmu from ``fmus/thirdparty``."""
    return rc.build_thirdparty(tmp_path_factory.mktemp("thirdparty"))


@pytest.fixture(scope="session")
def plant_fmus(fmu2_path: Path, thirdparty_fmu: Path) -> dict[str | None, Path]:
    """Plant FMU by case plant name (``None``: the project's FMI 2.0 four-tank)."""
    return {None: fmu2_path, rc.THIRDPARTY_PLANT: thirdparty_fmu}


@pytest.fixture(scope="session")
def regression_runs(request: pytest.FixtureRequest, plant_fmus: dict[str | None, Path],
                    tmp_path_factory: pytest.TempPathFactory) -> dict[str, rc.Run]:
    """Run every selected shipped case up front, two processes at a time (2-core CI)."""
    selected = []
    for item in request.session.items:
        case = getattr(item, "callspec", None) and item.callspec.params.get("case")
        if isinstance(case, rc.Case) and case not in selected:
            selected.append(case)
    runnable = [c for c in selected if rc.controller_available(c.controller) is None]
    return rc.run_cases(runnable, tmp_path_factory.mktemp("regression"), plant_fmus,
                        workers=2)
