"""The four-tank's control problem (``fmus/fourtank/problem.toml``) for tests that need it."""

from __future__ import annotations

from pathlib import Path

from controllers.problem_file import load

#: The shipped problem file of the four-tank.
PATH = Path(__file__).resolve().parents[1] / "fmus" / "fourtank" / "problem.toml"
#: The four-tank problem: qa, qb [m3/s] -> h1, h2 [m], Ts = 25 s.
FOURTANK = load(PATH)


def with_table(folder: Path, table: str, body: str) -> Path:
    """The four-tank's problem file with ``[table]`` of ``body`` appended, in ``folder``."""
    path = folder / "plant.toml"
    path.write_text(PATH.read_text() + f"\n[{table}]\n" + body)
    return path
