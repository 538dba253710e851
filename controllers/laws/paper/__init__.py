"""The paper's law (``law = "paper"``): ``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``) on the FHOCP
``eq:optimization`` with the set-point's reference ``(x̄, ū, α)``, its admissible reference
governor and the rejection of set-points outside the theory.

Its folder: :mod:`~controllers.laws.paper.reference` (the FHOCP's reference, the set-point
given with every solve), :mod:`~controllers.laws.paper.mpc` (``eq:mpc`` with the fallback of
the proof), :mod:`~controllers.laws.paper.governor` (the reference governor),
:mod:`~controllers.laws.paper.law` (the law with its set-point handling, and ``build``),
:mod:`~controllers.laws.paper.certify` (its hypotheses for ``cosim certify``),
:mod:`~controllers.laws.paper.export` (the C step's numbers and parameters) and its C files
``law.c`` and ``governor.c``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from controllers.laws import LawSpec, Option

__all__ = ["SPEC"]


def _bool(value: Any) -> str | None:
    return None if value is None or isinstance(value, bool) else "expected true or false"


def _rate(value: Any) -> str | None:
    from controllers.mpc_options import positive

    return (None if value is None or positive(value)
            else "expected a positive number of output units per sample")


_HERE = Path(__file__).resolve().parent

#: The paper's law: its section V's N = 15, the SQP's 15 iterations, the paper's cost (no
#: input-rate term), the governor on.
SPEC = LawSpec(
    name="paper", title="paper's law",
    defaults={"N": 15, "max_iter": 15, "offset_filter": 0.05, "du_weight": 0.0},
    options=(Option("governor", True, _bool, (None, False)),
             Option("offset_free", False, _bool, (False,)),
             Option("setpoint_rate", None, _rate)),
    foreign_note="(the default; the paper's law has no artificial steady state)",
    package=__name__, c_sources=(_HERE / "law.c", _HERE / "governor.c"))
