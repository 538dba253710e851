"""Fixtures for the co-simulation tests: FMUs from other exporters (pythonfmu, pythonfmu3), and
hostile C FMUs (:mod:`tests.cosim.hostile`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cosim import pyfmu_models


@pytest.fixture(scope="session")
def pyfmu_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with the test FMUs of :mod:`pyfmu_models` and the swap-in map."""
    dest = tmp_path_factory.mktemp("pyfmus")
    for kind in pyfmu_models.KINDS:
        pyfmu_models.build(kind, dest)
    (dest / "quadtank.map.toml").write_text(pyfmu_models.MAP)
    return dest


@pytest.fixture(scope="session")
def hostile_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with ``HostileController.fmu``, ``HostilePlant.fmu`` and ``libspin.so``,
    compiled from the C sources of :mod:`tests.cosim.hostile`."""
    from tests.cosim import hostile

    dest = tmp_path_factory.mktemp("hostile")
    for role in hostile.IDENTIFIERS:
        hostile.build(role, dest)
    hostile.build_spin(dest)
    return dest
