"""What a control law of the robust MPC is: the protocol every law implements, and what the
laws share.

:class:`controllers.mpc.RobustMPC` owns the observer, the held inputs, the units and the
certificate grade; everything that differs between laws -- the set-point handling, the
optimal-control problem and its reference, the law's own state and statistics -- lives in one
object implementing :class:`ControlLaw` that the law's spec builds (:mod:`controllers.laws`):
:class:`controllers.laws.paper.law.PaperLaw` (the paper's regulation law, ``eq:mpc``, with its
governor) and :class:`controllers.laws.tracking.law.TrackingLaw` (the artificial steady state
of MPC for tracking). A step of any law is a :class:`StepRecord` (:func:`solver_summary` sums
them up); :class:`LawContext` is what a spec builds a law from, :class:`Certified` what its
hypotheses give ``cosim certify``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from controllers.ocp.solver_settings import FEAS_TOL

if TYPE_CHECKING:
    from controllers.ocp.fhocp_result import FHOCPResult

__all__ = ["Certified", "ControlLaw", "LawContext", "LawStep", "Setting", "StepRecord",
           "refuse_r", "refuse_weight", "setpoint_text", "solver_summary"]


@dataclass(frozen=True)
class LawContext:
    """What a law is built from (:func:`build` of a law's module): the design's ``model``
    (its measured disturbances held in its biases) and its ``problem``, the certificate
    ``cert`` with the observer gains (``gains_certified``: a gain scale passed, else the
    gains are zero), the ``options`` (:class:`controllers.mpc_options.MPCOptions`), the
    certificate's design arguments ``kwargs`` (``N``, ``Q``, ``R``, ``e_o0``), the FHOCP's
    keyword arguments ``fhocp_options`` (solver, kernel, ``du_weight``) and the controller's
    ``name`` (messages)."""

    model: Any
    cert: Any
    gains_certified: bool
    options: Any
    kwargs: dict[str, Any]
    fhocp_options: dict[str, Any]
    name: str


@dataclass
class Certified:
    """What a law's hypotheses give ``cosim certify``: its ``verdict``
    (:class:`controllers.certification.diagnosis.Diagnosis`), what its JSON document adds
    (``report``) and the lines printed before the verdict."""

    verdict: Any
    report: dict[str, Any] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)


@dataclass
class LawStep:
    """One step of a law: the step record (:class:`controllers.laws.base.StepRecord`),
    whether the requested set-point was refused, the fraction of the way to it the reference
    governor moved (1: no governor, or all the way), and the law's own diagnostics (by
    name, in the problem's units)."""

    record: Any
    rejected: bool = False
    diagnostics: dict[str, float] = field(default_factory=dict)
    governor_lambda: float = 1.0


#: A setting of a law (what :meth:`ControlLaw.set` takes; the exported controller's tunable
#: parameter of the same name): ``(name, low, high, description, value)``.
Setting = tuple[str, float, float, str, float]


def refuse_r(R: np.ndarray, j: int, value: float) -> str:
    """Why ``value`` cannot be ``R``'s diagonal entry ``j`` (``""``: it keeps ``R`` positive
    definite, which every law's hypotheses need), as the C step says it."""
    r = np.array(R, dtype=float)
    r[j, j] = value
    if not np.isfinite(value):
        return "must keep R positive definite (a finite diagonal weight > 0)"
    try:
        np.linalg.cholesky(r)
    except np.linalg.LinAlgError:
        return "must keep R positive definite (a finite diagonal weight > 0)"
    return ""


def refuse_weight(value: float, positive: bool) -> str:
    """Why ``value`` cannot be a weight (``""``: it can): finite and ``> 0`` (``positive``)
    or ``>= 0``."""
    ok = np.isfinite(value) and (value > 0.0 if positive else value >= 0.0)
    return "" if ok else f"must be a finite weight {'>' if positive else '>='} 0"


def refuse_shared(name: str, value: float, R: np.ndarray, inputs: list[str]) -> str | None:
    """Why ``value`` cannot be setting ``name`` when it is one every law has (``""``: it can):
    ``offset_filter`` (the output-disturbance estimate's gain, in (0, 1]) or ``R.<input>``
    (:func:`refuse_r`); ``None`` for a law's own setting."""
    family, _, signal = name.partition(".")
    if family == "offset_filter":
        return "" if 0.0 < value <= 1.0 else "must be in (0, 1]"
    if family == "R":
        return refuse_r(R, inputs.index(signal), value)
    return None


def setpoint_text(model: Any, y: np.ndarray) -> str:
    """``"set-point CA=0.5 mol/L, T=345 K"``: the normalised ``y`` in the problem's names and
    units (``model.problem``'s)."""
    problem = model.problem
    return "set-point " + ", ".join(f"{n}={v:.4g} {u}".rstrip() for n, v, u in zip(
        problem.output_names, model.denormalize_y(y), problem.output_units, strict=True))


class ControlLaw(Protocol):
    """A control law of the robust MPC (module docstring); normalised units throughout."""

    #: the option value that selects it (``law="paper"``, ``law="tracking"``)
    name: str
    #: its optimal-control problem (``eq:optimization`` and its reference)
    fhocp: Any
    #: the certificate its tightening comes from
    cert: Any
    #: whether it takes operator limits on its outputs and lets an output leave its cost
    #: (``op.min``/``op.max`` of an output, ``op.control``; :mod:`controllers.mpc_operating`)
    output_limits: bool

    @property
    def records(self) -> list[Any]:
        """The step records of the run so far."""
        ...

    @property
    def alpha(self) -> float:
        """The terminal radius in use (``eq:def-alpha``)."""
        ...

    @property
    def steady_state(self) -> np.ndarray | None:
        """The steady state the FHOCP steers to now (the paper's ``x̄``, the tracking law's
        ``x_s``), ``None`` before the first step."""
        ...

    def reset(self) -> None:
        """Forget the run (set-points, plans, statistics)."""
        ...

    def step(self, observer: Any, y: np.ndarray, y_ref: np.ndarray, t: float,
             x_start: np.ndarray | None = None) -> LawStep:
        """``u_k`` for the measured ``y`` and the requested ``ȳ``, at ``x̂`` and ``ê_o`` of
        ``observer`` (which the controller advances afterwards); ``x_start``: the state the
        FHOCP starts from instead of ``x̂`` (``x̂`` predicted over the inputs' dead time,
        :mod:`controllers.dead_time`)."""
        ...

    def disturbance_moved(self, measured: str) -> None:
        """The measured disturbances the FHOCP holds moved (the model's biases hold the new
        values, :class:`controllers.disturbances.BiasShift`; ``measured``: them in the user's
        names and units, for messages): the law's equilibria follow."""
        ...

    def restart(self) -> None:
        """After a fallback whose candidate was infeasible with disturbances measured: what
        the law starts again from (the tracking law: its steady state)."""
        ...

    def setpoint_reason(self, y: np.ndarray) -> str:
        """Why the certified design does not cover the set-point ``y``, one line naming it
        (:func:`setpoint_text`; empty: it does)."""
        ...

    def uncertified(self, cert: Any, reason: str) -> ControlLaw:
        """The same law on the uncertified certificate ``cert`` (its measured tightening);
        raises :class:`cosim.core.errors.CosimError` when even that leaves nothing to control
        (``reason``: why the run is uncertified)."""
        ...

    def summary(self) -> dict[str, Any]:
        """The law's entries of the run summary (its statistics and design)."""
        ...

    def settings(self) -> list[Setting]:
        """What may change between steps (:data:`Setting`), in the C step's order of its
        tunable parameters, with their values now."""
        ...

    def set(self, name: str, value: float) -> str:
        """Setting ``name`` (one of :meth:`settings`, checked) from the next step on; what
        it changed, in words."""
        ...

    def refuse(self, name: str, value: float) -> str:
        """Why setting ``name`` cannot take ``value`` (``""``: it can)."""
        ...

    def applied(self, u: np.ndarray) -> None:
        """The inputs the plant got this step (normalised; the operator's, held or limited
        ones may differ from the law's, :mod:`controllers.operator`): its ``u_{−1}`` of the
        next step."""
        ...

    def control(self, controlled: np.ndarray) -> str:
        """Keep in the cost only the outputs ``controlled`` (a bool mask; ``op.control``):
        what changed, or why the law refuses it (raises
        :class:`~controllers.errors.OptionError`)."""
        ...


@dataclass
class StepRecord:
    """What happened at one controller step (normalised units).

    Attributes
    ----------
    u : (m,) array
        Applied input.
    result : FHOCPResult
        The solve (its ``status`` says why a fallback happened).
    fallback : bool
        The shifted previous solution (``ū`` appended) was applied instead of the optimum.
    candidate_feasible : bool
        For a fallback: whether that shifted sequence satisfies the FHOCP constraints at
        ``x̂_k`` (Theorem 3 says it does when its hypotheses hold).
    """

    u: np.ndarray
    result: FHOCPResult
    fallback: bool
    candidate_feasible: bool = True
    suboptimal: bool = False
    x_hat: np.ndarray | None = None
    e_o: float = 0.0


def solver_summary(records: list[StepRecord]) -> dict[str, Any]:
    """Median / p99 / max solve time [ms], iterations, failures by status, fallbacks, the
    steps whose applied plan exceeds a softened row (:mod:`controllers.ocp.soft`) by more
    than :data:`~controllers.ocp.solver_settings.FEAS_TOL` and the largest such excess
    (normalised)."""
    if not records:
        return {"steps": 0}
    t = np.array([r.result.solve_time for r in records]) * 1e3
    it = np.array([r.result.iterations for r in records])
    statuses: dict[str, int] = {}
    for r in records:
        if not r.result.success:
            key = r.result.status.split(":")[0]
            statuses[key] = statuses.get(key, 0) + 1
    return {
        "steps": len(records),
        "solve_ms_median": float(np.median(t)),
        "solve_ms_p99": float(np.percentile(t, 99)),
        "solve_ms_max": float(np.max(t)),
        "iterations_median": float(np.median(it)),
        "iterations_max": int(np.max(it)),
        "failures": int(sum(statuses.values())),
        "failures_by_status": statuses,
        "fallbacks": int(sum(r.fallback for r in records)),
        "suboptimal_steps": int(sum(r.suboptimal for r in records)),
        "softened_steps": int(sum(r.result.softened > FEAS_TOL and not r.fallback
                                  for r in records)),
        "softened_max": float(max(r.result.softened for r in records)),
        "fallback_candidates_infeasible": int(sum(r.fallback and not r.candidate_feasible
                                                  for r in records)),
    }
