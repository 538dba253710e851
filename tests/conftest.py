"""Shared pytest fixtures: the built four-tank plant FMUs and the exported controller FMUs.

Tests that need a real FMU take ``fmu2_path`` (FMI 2.0) or ``fmu3_path`` (FMI 3.0). The FMUs
are built once per session by :func:`cosim.core.build.build_fmus`, which only recompiles when the
C sources changed. ``controller_fmus`` is the default robust MPC exported by ``cosim
export-fmu`` for FMI 2 and 3, once per session.
"""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def fmu_paths() -> list[Path]:
    """Both plant FMUs, built if needed: ``[FourTank.fmu, FourTank3.fmu]``."""
    from cosim.core.build import build_fmus

    return build_fmus()


@pytest.fixture(scope="session")
def fmu2_path(fmu_paths: list[Path]) -> Path:
    """``fmus/FourTank.fmu``: the FMI 2.0 plant (Co-Simulation and Model Exchange)."""
    return fmu_paths[0]


@pytest.fixture(scope="session")
def fmu3_path(fmu_paths: list[Path]) -> Path:
    """``fmus/FourTank3.fmu``: the FMI 3.0 plant (Co-Simulation and Model Exchange)."""
    return fmu_paths[1]


@pytest.fixture(scope="session")
def controller_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """The default robust MPC of the shipped model as controller FMUs, by FMI version
    (``Controller2.fmu``, ``Controller3.fmu``)."""
    from cosim.cli import main

    out = tmp_path_factory.mktemp("controller")
    fmus = {v: out / f"Controller{v}.fmu" for v in (2, 3)}
    for version, path in fmus.items():
        assert main(["export-fmu", "--fmi", str(version), "--out", str(path), "--quiet"]) == 0
    return fmus


#: The test modules that take minutes, longest first (measured on 2 cores: the verdicts' 5
#: cases about 4 min together, each example plant's walk-through 2.5 to 3.5 min, the others 1 to
#: 2.5 min): ``pytest -n 2 --dist loadscope --no-loadscope-reorder`` (the Makefile's) hands the
#: workers their scopes in collection order, so these start first, and a worker that finishes
#: early takes the short modules left instead of waiting while the other runs a long one.
SLOW_FIRST = ("tests/cosim/commands/test_verdicts_agree.py", "tests/test_example_plants.py",
              "tests/benchmarks/test_disturbance_campaign.py", "tests/test_wheel.py",
              "tests/cosim/live/test_vendor_plc.py",
              "tests/cosim/campaign/test_campaign_deployments.py",
              "tests/benchmarks/test_bench_tune.py", "tests/regression/test_robustness.py",
              "tests/regression/test_scenarios.py",
              "tests/cosim/campaign/test_campaign_engine.py",
              "tests/cosim/commands/test_cli_tune.py", "tests/cosim/live/test_faceplate.py",
              "tests/benchmarks/test_bench_zoo.py")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The modules of :data:`SLOW_FIRST` first, in its order; every other test after them,
    in the order collected (the order within a module kept)."""
    def rank(item: pytest.Item) -> int:
        path = item.nodeid.split("::")[0]
        return SLOW_FIRST.index(path) if path in SLOW_FIRST else len(SLOW_FIRST)

    items.sort(key=rank)
