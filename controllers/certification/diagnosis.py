"""Which hypotheses of the theorem hold for a model, in the user's signals and units, and
what would fix the ones that fail.

A :class:`~controllers.certification.certificates.Certificate` speaks the paper's symbols (ν,
w̄_y, a_N, α…). A user needs: does my model give a certified controller for the set-points I
want; if not, which hypothesis fails, by how much, in my units, and what to do. :func:`diagnose`
answers that for either law of the robust MPC:

- **stability** (``th:stability-bonassi``): ν < 1; a model without it has no certificate and
  cannot be used (``cosim train`` never writes one);
- **design**: the paper's law, the observer condition ν_o < 1
  (``eq:condition-observer-convergence``); the tracking law, its hypotheses H3–H6
  (:mod:`controllers.laws.tracking.checks`);
- **room in the box**: the output constraints are tightened, at the end of the horizon, by
  the model's output-error bound ``w̄_y`` and by the estimation-error and terminal-set terms;
  what is left is the set of set-points that pass (``Y_s`` for the tracking law, the box of
  Assumption 1 and ``eq:condition-recursive-feasibility`` for the paper's), per output in its
  units;
- **each set-point** asked for: inside that set, or by how much it is outside; and the
  largest ``w̄_y`` (in each output's units) with which every one of them would pass
  (:func:`required_error`), when there is one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.certification.certificates import NU_FIX
from controllers.certification.output_ranges import box_ranges

__all__ = ["Diagnosis", "Finding", "diagnose", "dominant_part", "required_error",
           "tightening_parts"]


@dataclass
class Finding:
    """One hypothesis: whether it holds, the numbers, and what would fix it."""

    hypothesis: str
    holds: bool
    detail: str
    fix: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"hypothesis": self.hypothesis, "holds": self.holds, "detail": self.detail,
                "fix": self.fix or None}


@dataclass
class Diagnosis:
    """The verdict of :func:`diagnose`.

    Attributes
    ----------
    law : str
    certified : bool
        Every finding holds.
    usable : bool
        The robust MPC runs with this model (certified, or uncertified with a measured
        tightening): :meth:`~controllers.certification.certificates.Certificate.unusable`
        names no reason.
    findings : list of Finding
    admissible : list of (name, lo, hi)
        The set-points that pass, per output, physical units (``None``: none).
    required_w_y_bar : float or None
        The largest ``w̄_y`` (normalised) with which the set-points asked for would pass.
    unusable : str
        Why the model is not usable, with what would fix it (``""`` when it is).
    """

    law: str
    certified: bool
    usable: bool
    findings: list[Finding] = field(default_factory=list)
    admissible: list[tuple[str, float | None, float | None]] = field(default_factory=list)
    required_w_y_bar: float | None = None
    unusable: str = ""

    def reasons(self) -> list[str]:
        """The failing hypotheses, one line each."""
        return [f"{f.hypothesis}: {f.detail}" for f in self.findings if not f.holds]

    def to_json(self) -> dict[str, Any]:
        return {"law": self.law, "certified": self.certified, "usable": self.usable,
                "unusable_reason": self.unusable or None,
                "findings": [f.to_json() for f in self.findings],
                "admissible_setpoints": {n: None if lo is None else [lo, hi]
                                         for n, lo, hi in self.admissible},
                "required_w_y_bar": self.required_w_y_bar}


def required_error(passes: Callable[[float], bool], current: float,
                   iterations: int = 40) -> float | None:
    """The largest ``w̄_y`` in ``[0, current]`` for which ``passes(w̄_y)`` holds (bisection;
    ``passes`` is monotone: a smaller error never tightens more); ``None`` when even
    ``w̄_y = 0`` fails."""
    if not passes(0.0):
        return None
    if passes(current):
        return current
    lo, hi = 0.0, current
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if passes(mid) else (lo, mid)
    return lo


def _units(model: Any, value: float) -> str:
    """A normalised output error as each output's physical size."""
    return ", ".join(f"{value * abs(float(s)):.3g} {u} on {n}".replace("  ", " ")
                     for n, s, u in zip(model.output_names, model.y_scale,
                                        model.output_units, strict=True))


def _interval_text(ranges: Sequence[tuple[str, float | None, float | None]],
                   units: Sequence[str]) -> str:
    return "; ".join(f"{n} in [{lo:.4g}, {hi:.4g}] {u}".rstrip() if lo is not None
                     else f"{n}: none" for (n, lo, hi), u in zip(ranges, units, strict=True))


def _setpoint_text(model: Any, y: np.ndarray) -> str:
    return ", ".join(f"{n}={v:.4g} {u}".rstrip() for n, v, u in zip(
        model.output_names, model.denormalize_y(y), model.output_units, strict=True))


def tightening_parts(model: Any, cert: Any, tightening: np.ndarray
                     ) -> list[tuple[str, np.ndarray, str]]:
    """The parts of the end-of-horizon tightening ``tightening`` (q,; normalised) of the
    certificate ``cert``, each with what shrinks it: the estimation error ``ẽ_o a_N``
    (``lem:Vo``), the output error carried over the horizon (``b_N`` of
    ``eq:constraint_tightening_parameters`` without the held disturbances), the measured
    disturbances held over the horizon (``lem:held-disturbance``), the output noise ``w_L``,
    and the rest (the terminal set's ``α c_s``)."""
    N = cert.N
    held = (np.zeros_like(cert.w_L) if cert.b_held is None
            else np.asarray(cert.b_held[N], dtype=float))
    parts = [
        ("the estimation error (e_o a_N)", cert.e_tilde * cert.a[N],
         "observer gains (gain_scale), a smaller e_o0, a model that contracts faster "
         "(cosim train --rho-max), or a shorter horizon N"),
        ("the output error carried over the horizon (b_N)", cert.b[N] - held,
         "a model with a smaller test error, smaller observer gains, or a shorter horizon N"),
        ("the measured disturbances held over the horizon", held, _held_fix(model)),
        ("the output noise (w_L)", np.asarray(cert.w_L, dtype=float),
         "a model with a smaller test error"),
    ]
    with np.errstate(invalid="ignore", over="ignore"):   # a model with no bound: inf - inf
        rest = tightening - sum(p[1] for p in parts)
    parts.append(("the terminal set", rest, "a smaller terminal radius (alpha_c)"))
    return parts


def dominant_part(model: Any, cert: Any, tightening: np.ndarray) -> tuple[str, float, str]:
    """``(part, share, what shrinks it)``: the largest part (:func:`tightening_parts`) of the
    most tightened row and its share of that row's tightening."""
    row = int(np.argmax(tightening))
    parts = tightening_parts(model, cert, tightening)
    name, values, fix = max(parts, key=lambda p: float(p[1][row]))
    total = float(tightening[row])
    return name, float(values[row]) / total if total > 0 else 0.0, fix


def _held_fix(model: Any) -> str:
    """What shrinks the held disturbances' term: each one's declared largest change per
    sample (now the data's, or the whole box), its preview, or a shorter horizon."""
    full = getattr(model, "held_from", None) or model   # the model with its disturbances
    dists = list(getattr(getattr(full, "problem", None), "disturbances", ()) or ())
    if not dists:
        return "a shorter horizon N"
    undeclared = [c.name for c in dists if c.rate is None]
    how = (f"declaring how fast {', '.join(undeclared)} can move ([disturbances.<name>] "
           f"rate, now the identification data's largest change per sample) or "
           if undeclared else "a smaller declared rate, ")
    return f"{how}preview = true, or a shorter horizon N"


def diagnose(model: Any, cert: Any, law: str, setpoints: Sequence[np.ndarray],
             admissible_rhs: np.ndarray, design_failures: Sequence[str],
             rhs_at: Callable[[float], np.ndarray] | None = None) -> Diagnosis:
    """The findings for ``model`` and its certificate ``cert`` under ``law``.

    Parameters
    ----------
    setpoints : sequence of (p,) arrays
        The set-points asked for (normalised; may be empty).
    admissible_rhs : (q,) array
        The right-hand side of the set-points that pass, ``{y : L y ≤ rhs}`` (the tracking
        law's ``Y_s``; the paper law's :meth:`Certificate.admissible_box`).
    design_failures : sequence of str
        The law's design hypotheses that fail (the paper's ν_o, the tracking law's H3–H6).
    rhs_at : callable, optional
        ``admissible_rhs`` as a function of ``w̄_y`` (normalised; for :func:`required_error`).
    """
    units = list(model.output_units)
    findings = [Finding("stability (δISS, th:stability-bonassi)", cert.nu < 1,
                        f"stability index nu = {cert.nu:.4g} " + ("< 1" if cert.nu < 1
                                                                    else ">= 1"),
                        "" if cert.nu < 1 else NU_FIX)]
    findings += [Finding(f"{law} law design", False, msg, "see the docs' certificates "
                         "guide") for msg in design_failures]
    ranges = box_ranges(model, cert.L, admissible_rhs)
    box = box_ranges(model, cert.L, cert.h)
    tightening = cert.h - admissible_rhs
    part, share, shrink = dominant_part(model, cert, tightening)
    room = Finding(
        "room for set-points", all(lo is not None for _, lo, _ in ranges),
        f"the constraints are tightened by the model's largest test error "
        f"({_units(model, cert.w_y_bar)}) and by what the horizon adds to it "
        f"(in all, {_units(model, float(np.max(tightening)))} at most; "
        f"{100 * share:.0f} % of it {part}): set-points that "
        f"pass: {_interval_text(ranges, units)}, of the box {_interval_text(box, units)}")
    findings.append(room)
    outside = [y for y in setpoints if np.any(cert.L @ y > admissible_rhs + 1e-12)]
    required = None
    if outside or not room.holds:
        targets = list(setpoints) or []
        if rhs_at is not None:
            def passes(w: float) -> bool:
                rhs = rhs_at(w)
                if not targets:
                    return all(lo is not None for _, lo, _ in box_ranges(model, cert.L, rhs))
                return all(np.all(cert.L @ y <= rhs + 1e-12) for y in targets)

            required = required_error(passes, float(cert.w_y_bar))
        fix = ("train longer (--epochs) or on more data, or widen the output box if the "
               "plant allows it")
        if required is not None and required < cert.w_y_bar:
            fix = (f"a model whose largest test error is below {_units(model, required)} "
                   f"would pass: {fix}")
        elif required is None and rhs_at is not None:
            fix = (f"even an exact model would not pass (what the horizon adds fills the box; "
                   f"its largest part, {part}, shrinks with {shrink})")
        elif share > 0.5:
            fix = f"{part} is most of the tightening: it shrinks with {shrink}; or {fix}"
        room.fix = fix if not room.holds else ""
        for y in outside:
            findings.append(Finding(
                "set-point", False,
                f"{_setpoint_text(model, y)} is outside the set-points that pass "
                f"({_interval_text(ranges, units)})", fix))
    certified = all(f.holds for f in findings)
    return Diagnosis(law=law, certified=certified, usable=not cert.unusable(),
                     unusable=cert.unusable(),
                     findings=findings, admissible=ranges, required_w_y_bar=required)
