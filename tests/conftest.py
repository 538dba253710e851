"""Shared pytest fixtures: the built four-tank plant FMUs.

Tests that need a real FMU take ``fmu2_path`` (FMI 2.0) or ``fmu3_path`` (FMI 3.0). The FMUs
are built once per session by :func:`cosim.core.build.build_fmus`, which only recompiles when the
C sources changed.
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
