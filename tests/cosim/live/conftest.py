"""A real ``cosim serve-plant`` in its own process on 127.0.0.1, for the live-plant tests.

:func:`served` starts one on a free port (:mod:`cosim.live.process`), waits (bounded) until
it listens, and stops it (SIGTERM, then SIGKILL) however the test ends; nothing is mocked.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path

import pytest

from cosim.live.process import ServedPlant, free_port, start_served_plant

__all__ = ["ROOT", "cosim", "env", "free_port", "problem_with", "served", "start"]

ROOT = Path(__file__).resolve().parents[3]


def env(**extra: str) -> dict[str, str]:
    """The environment of a ``cosim`` subprocess (the repository importable)."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra)


def cosim(*args: str) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", *args]


def start(tmp: Path, *args: str, port: int | None = None, extra_env: dict | None = None,
          name: str = "server") -> ServedPlant:
    """``cosim serve-plant ARGS`` on ``port`` (a free one by default), its log in ``tmp``;
    once it listens (30 s at most: :func:`cosim.live.process.start_served_plant`)."""
    return start_served_plant(*args, log=tmp / f"{name}.log", port=port,
                              env=env(**(extra_env or {})))


@contextlib.contextmanager
def served(tmp: Path, *args: str, **kw: object) -> Iterator[ServedPlant]:
    """:func:`start` for the ``with`` block; stopped after it, however it ends."""
    server = start(tmp, *args, **kw)  # type: ignore[arg-type]
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def short_scenario(tmp_path: Path) -> Path:
    """The paper's first set-point steps, shortened: 60 samples of 25 s."""
    path = tmp_path / "short.csv"
    path.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n500,0.9,\n1000,,1.0\n1500,,\n")
    return path


def problem_with(path: Path, keys: Mapping[str, str]) -> Path:
    """The four-tank's problem file with more keys in the tables of some signals (``{"qa":
    "safe = 0.0", "h1": "frozen = 3"}``), written to ``path``."""
    from cosim.adapters.problems import default_problem_path

    text = default_problem_path().read_text()
    for signal, line in keys.items():
        kind = "inputs" if signal.startswith("q") else "outputs"
        header = f"[{kind}.{signal}]\n"
        assert header in text, header
        text = text.replace(header, f"{header}{line}\n")
    path.write_text(text)
    return path


@pytest.fixture
def safe_problem(tmp_path: Path) -> Path:
    """The four-tank's problem with safe inputs (qa = 0, qb held)."""
    return problem_with(tmp_path / "problem_safe.toml", {"qa": "safe = 0.0"})
