"""A toy third law, ``steady``, in one folder: the test that a law is one folder (issue 59).

``u_k`` is the equilibrium input of the set-point (the model's static inverse: no feedback
but the observer's), on a tracking FHOCP's compiled kernel whose equilibrium search it calls
(never solving the FHOCP). Named by its module path (``law =
"tests.controllers.laws.steady"``); nothing outside this folder knows it.
"""

from __future__ import annotations

from pathlib import Path

from controllers.laws import LawSpec

SPEC = LawSpec(
    name="steady", title="steady-state law",
    defaults={"N": 10, "max_iter": 15, "offset_filter": 0.3, "du_weight": 0.0},
    foreign_note="(the steady-state law has no such option)",
    package=__name__, c_sources=(Path(__file__).resolve().with_name("law.c"),))
