"""The four-tank's control problem (``fmus/fourtank/problem.toml``) for tests that need it."""

from __future__ import annotations

from pathlib import Path

from controllers.problem_file import load

#: The shipped problem file of the four-tank.
PATH = Path(__file__).resolve().parents[1] / "fmus" / "fourtank" / "problem.toml"
#: The four-tank problem: qa, qb [m3/s] -> h1, h2 [m], Ts = 25 s.
FOURTANK = load(PATH)
