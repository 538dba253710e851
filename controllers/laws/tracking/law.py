"""The tracking law (``law = "tracking"``, the default) of the robust MPC.

:class:`controllers.mpc.RobustMPC` with ``law="tracking"`` runs
:class:`controllers.laws.tracking.mpc.TrackingMPC` (the tracking FHOCP of
:mod:`controllers.laws.tracking.reference`: artificial steady state, offset cost with the
disturbance estimate ``d̂``, input-rate penalty) instead of the paper's law with its reference
governor. This module builds it from the model and the problem (:func:`build`,
:func:`tracking_design`) and runs it (:class:`TrackingLaw`, a :class:`controllers.laws.base.
ControlLaw`); the design record is docs/design/tracking.md.

Design (defaults):

- observer gains zero (``L_z = L_r = 0``: the GRU observer runs the model; ν_o = ν, κ = 0,
  w̄ = 0), so the steady state the observer settles in is the model's, which makes the
  offset-free fixed point exact; ``ê_o`` and the tightening as the paper's;
- the terminal radius ``α_c``: the certified design's ``α_min(N)`` (``eq:condition-recursive-
  feasibility`` with the gains the paper's law would use), so that ``Y_s`` is that design's
  admissible box; when no observer-gain scale passes (that ``α_min`` is not a certificate's),
  the radius whose terminal set spans :data:`ALPHA_C_SPAN` of each normalised output; with
  zero gains every ``α_c > 0`` meets ``eq:condition-recursive-feasibility``; ``alpha_c`` sets
  it;
- ``d̂`` by the filter of :class:`controllers.laws.tracking.mpc.DisturbanceFilter` (``β`` =
  ``offset_filter``, default 0.3), in the cost only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from controllers.errors import OptionError
from controllers.laws.base import (
    LawContext,
    LawStep,
    Setting,
    refuse_shared,
    refuse_weight,
    setpoint_text,
)

__all__ = ["ALPHA_C_SPAN", "UNCERTIFIED_ALPHA_C", "TrackingLaw", "build", "fallback_alpha_c",
           "settings_of", "steady_outputs_text", "tracking_design"]

#: How far a target may lie beyond ``Y_s`` (normalised) before it is noted
#: (:meth:`TrackingLaw._watch_target`).
TARGET_TOL = 1e-6
#: At most this many notes of targets outside ``Y_s`` in a run's summary.
MAX_NOTES = 5
#: The terminal radius of a design without a certified ``α_min`` (no observer-gain scale
#: passes, or the uncertified mode): the one whose terminal set spans this much of every
#: normalised output (``α_c max_j c_s(j)``; the normalised box is 2 wide).
ALPHA_C_SPAN = 0.05
#: The uncertified mode's terminal radius (``‖x_N − x_s‖∞``; GRU states lie in the unit box,
#: so 2 bounds nothing): without a guarantee to keep, the terminal set only held the
#: artificial steady state to where the horizon's slowest hidden modes could reach, and it
#: crawled after a set-point step (the zoo's air heater: the steady output 60 °C for a 45 °C
#: set-point, the terminal set active; docs: design/soft-constraints.md,
#: ``rem:uncertified-terminal``). The terminal cost ``s t²`` (the measured weight) stays.
UNCERTIFIED_ALPHA_C = 2.0


def fallback_alpha_c(cert: Any) -> float:
    """:data:`ALPHA_C_SPAN` ``/ max_j c_s(j)``: depends on the model's output map only."""
    top = float(np.max(cert.c_s)) if np.size(cert.c_s) else 0.0
    return ALPHA_C_SPAN / top if top > 0 else ALPHA_C_SPAN


def tracking_design(model: Any, cert_gains: Any, design: Mapping[str, Any],
                    gains_certified: bool = True, cert: Any = None, measured: bool = False
                    ) -> tuple[Any, Any, Any, list[str]]:
    """``(certificate, TrackingMPC, DisturbanceFilter, failures)`` of the tracking law
    (module docstring) on ``model`` (and its ``problem``); ``failures``: its hypotheses that
    fail, in words (empty: certified). ``design``: ``kwargs`` (``N``, ``Q``, ``R``,
    ``e_o0``), ``offset_weight``, ``alpha_c``, ``offset_filter`` (``β``), ``fhocp_options``
    and ``control_horizon`` (``M``; default :func:`controllers.laws.tracking.reference.
    default_control_horizon`, at most N). ``cert_gains``: the paper law's certificate, whose
    ``α_min`` is the default ``α_c`` when ``gains_certified`` (its observer-gain scale
    passed), else :func:`fallback_alpha_c`; ``cert``: the design's certificate (default:
    ``gain_scale=0`` of ``kwargs``; the uncertified mode passes
    :func:`controllers.certification.grade.uncertified_certificate`'s). ``measured``: that
    uncertified design: the terminal radius :data:`UNCERTIFIED_ALPHA_C` unless one is given,
    and ``Y_s`` the box tightened by the measured margin alone (``h − b_N``, no ``α_c c_s``:
    that term keeps the theorem's terminal set inside the constraints, which the uncertified
    mode does not claim)."""
    from controllers.certification import certificates as certs
    from controllers.laws.tracking import SPEC
    from controllers.laws.tracking.checks import failures, tracking_hypotheses
    from controllers.laws.tracking.mpc import DisturbanceFilter, TrackingMPC
    from controllers.laws.tracking.reference import ArtificialSteadyState, default_control_horizon
    from controllers.ocp.fhocp import FHOCP

    problem, kwargs = model.problem, design["kwargs"]
    offset_weight, alpha_c = design["offset_weight"], design["alpha_c"]
    beta, control_horizon = design["offset_filter"], design["control_horizon"]
    names = list(problem.output_names)
    default = float(SPEC.option("offset_weight").default)
    if offset_weight is None:
        offset_weight = default
    if isinstance(offset_weight, Mapping):
        unknown = sorted(set(offset_weight) - set(names))
        if unknown:
            raise OptionError(f"option offset_weight: {unknown[0]!r} is not an output of "
                              f"problem {problem.name!r} ({', '.join(names)})")
        T = np.array([float(offset_weight.get(n, default)) for n in names])
    else:
        T = np.full(len(names), float(offset_weight))
    N = int(kwargs["N"])
    M = default_control_horizon(N) if control_horizon is None else control_horizon
    if M > N:
        raise OptionError(f"option control_horizon={M}: at most the horizon N = {N}")
    if cert is None:
        cert = certs.compute_certificate(model, gain_scale=0.0, **kwargs)
    if alpha_c is None and measured:
        alpha_c = UNCERTIFIED_ALPHA_C
    elif alpha_c is None:
        alpha_c = cert_gains.alpha_min() if gains_certified else math.nan
        if not (math.isfinite(alpha_c) and alpha_c > 0):
            alpha_c = fallback_alpha_c(cert)
    ys = cert.h - cert.b[cert.N] if measured else None
    reference = ArtificialSteadyState(T, alpha_c, ys_bounds=ys, control_horizon=M)
    fhocp = FHOCP.from_certificate(cert, reference=reference, **design["fhocp_options"])
    hypotheses = tracking_hypotheses(fhocp, cert, beta)
    law = TrackingMPC(fhocp)
    law.hypotheses = hypotheses
    return cert, law, DisturbanceFilter(beta, len(names)), failures(hypotheses)


def build(ctx: LawContext) -> tuple[TrackingLaw, list[str]]:
    """The tracking law of the design ``ctx`` (:func:`tracking_design`: its certificate at
    zero observer gains, ``α_c`` from the paper law's certificate ``ctx.cert``) and its
    hypotheses that fail (:mod:`controllers.laws`)."""
    o = ctx.options
    design = {"kwargs": ctx.kwargs, "fhocp_options": ctx.fhocp_options,
              "offset_weight": o.option("offset_weight"), "alpha_c": o.option("alpha_c"),
              "offset_filter": o.offset_filter, "control_horizon": o.option("control_horizon")}
    cert, tracker, disturbance, failed = tracking_design(ctx.model, ctx.cert, design,
                                                         ctx.gains_certified)
    return TrackingLaw(ctx.model, cert, tracker, disturbance, design, ctx.name), failed


def settings_of(beta: float, R: np.ndarray, du: np.ndarray | None, T: np.ndarray,
                inputs: list[str], outputs: list[str]) -> list[Setting]:
    """The tracking law's settings (the C step's tunable parameters, ``law.c``'s
    ``LAW_P_*`` order), with these values: the disturbance filter's gain, the diagonal of
    ``R``, the input-rate weights (``du``: with the term), the offset weights ``T``."""
    inf = float("inf")
    out = [("offset_filter", 0.0, 1.0, "gain of the output-disturbance estimate d_hat, in "
            "(0, 1] (option offset_filter)", float(beta))]
    out += [(f"R.{name}", 0.0, inf, f"input weight R of {name} (diagonal entry; R stays "
             "positive definite; option R)", float(R[j, j])) for j, name in enumerate(inputs)]
    if du is not None:
        out += [(f"du_weight.{name}", 0.0, inf, f"input-rate weight S of {name}, >= 0 "
                 "(option du_weight)", float(du[j])) for j, name in enumerate(inputs)]
    out += [(f"offset_weight.{name}", 0.0, inf, f"offset weight T of {name}, > 0 "
             "(option offset_weight)", float(T[a])) for a, name in enumerate(outputs)]
    return out


class TrackingLaw:
    """The tracking law (module docstring), a :class:`controllers.laws.base.ControlLaw`.

    Parameters
    ----------
    model : GRUModel
    cert : Certificate
        The design's certificate (``gain_scale = 0``, or the uncertified one).
    tracker : TrackingMPC
    disturbance : DisturbanceFilter
    design : dict
        What :func:`tracking_design` was given (``kwargs``, ``offset_weight``, ``alpha_c``,
        ``offset_filter``, ``fhocp_options``, ``control_horizon``): the uncertified mode
        builds the law again from it.
    name : str
        The component's name (in error messages).
    certified : bool
        Uncertified: the output rows are tightened around ``y + d̂``.
    """

    name = "tracking"
    #: operator limits on its outputs and outputs out of its cost (controllers.mpc_operating)
    output_limits = True

    def __init__(self, model: Any, cert: Any, tracker: Any, disturbance: Any,
                 design: Mapping[str, Any], name: str, certified: bool = True) -> None:
        self.model, self.cert, self.tracker, self.disturbance = model, cert, tracker, disturbance
        self.fhocp = tracker.fhocp
        self.design = dict(design)
        #: the outputs in the offset cost (``op.control``), and the engineer's ``T``
        self.controlled = np.ones(model.problem.p, dtype=bool)
        self._offset_weights = np.array(self.fhocp.reference.offset_weight, dtype=float)
        self.component = name
        self.certified = certified
        self.reset()

    # -- ControlLaw ------------------------------------------------------------------------
    @property
    def alpha(self) -> float:
        return self.fhocp.reference.alpha_c

    @property
    def records(self) -> list[Any]:
        return self.tracker.records

    @property
    def steady_state(self) -> np.ndarray | None:
        return self.tracker.x_s

    def reset(self) -> None:
        self.tracker.reset()
        self.disturbance.reset()
        self.y_ref: np.ndarray | None = None
        self.setpoint_changes = 0
        #: times :meth:`restart` was called
        self.restarts = 0
        #: per set-point whose target left ``Y_s``: its first time, steps, last target, d̂
        self.outside: dict[int, dict[str, Any]] = {}
        #: set-points the measured disturbances left unreachable (notes), the last one
        #: pending its step's time
        self.moved_notes: list[str] = []
        self._moved_note = ""

    def step(self, observer: Any, y: np.ndarray, y_ref: np.ndarray, t: float,
             x_start: np.ndarray | None = None) -> LawStep:
        """``d̂`` advanced with ``y − g(x̂)``, the FHOCP solved for ``r = ȳ − d̂``; the
        diagnostics ``y_model_<output>`` (the steady output ``y_s``) and ``d_hat_<output>``
        (``d̂``), in the problem's units."""
        from controllers.equilibrium import equilibrium_for_output

        if self.y_ref is None or np.any(y_ref != self.y_ref):
            self.setpoint_changes += 1
            self.y_ref = y_ref
        if self._moved_note and len(self.moved_notes) < MAX_NOTES:
            self.moved_notes.append(f"from t = {t:g} s, {self._moved_note}")
        self._moved_note = ""
        tracker, model = self.tracker, self.model
        if tracker.u_s is None:   # the equilibrium x̂_0 starts at
            x_s, u_s = equilibrium_for_output(model.params, observer.y_hat(), self.fhocp.kernel)
            tracker.start(u_s, x_s)
        d_hat = self.disturbance.update(y, observer.y_hat())
        if not self.certified:   # the measured tightening is around y + d̂
            self.fhocp.set_output_shift(d_hat)
        self._watch_target(y_ref - d_hat, d_hat, t)
        x0 = observer.x_hat if x_start is None else x_start
        rec = tracker.make_step(x0, observer.e_o, y_ref - d_hat)
        params, kernel = model.params, self.fhocp.kernel
        y_s = model.denormalize_y(kernel.output(tracker.x_s) if kernel is not None   # the
                                  else params["U_o"] @ tracker.x_s + params["b_o"])  # FMU's sum
        names = model.problem.output_names
        diag = {f"y_model_{n}": float(v) for n, v in zip(names, y_s, strict=True)}
        d_phys = d_hat * np.abs(model.y_scale)
        diag.update({f"d_hat_{n}": float(v) for n, v in zip(names, d_phys, strict=True)})
        return LawStep(rec, False, diag)

    def disturbance_moved(self, measured: str = "") -> None:
        """The measured disturbances moved (the model's biases hold the new values): keep
        the artificial steady state's output where it was, with the steady input the model
        now needs for it (the equilibrium for that output at the new disturbances, the
        nonlinear static feedforward), and move the plan by the same input change. Without
        it, the steady state would lag behind by the move limit on ``u_s`` and the stage cost
        would pull the outputs towards that lagging state. A set-point the new disturbances
        leave unreachable (``measured``: them in the user's names) is tracked to the closest
        reachable steady output, as any, and named in :meth:`notes`."""
        from controllers.equilibrium import equilibrium_for_output

        tracker, kernel = self.tracker, self.fhocp.kernel
        if tracker.u_s is None or tracker.x_s is None:
            return
        params = self.model.params
        y_s = kernel.output(tracker.x_s) if kernel is not None else \
            params["U_o"] @ tracker.x_s + params["b_o"]
        x_s, u_s = equilibrium_for_output(params, y_s, kernel)
        u_s = np.clip(u_s, -1.0, 1.0)
        if tracker.plan is not None:
            tracker.plan = np.clip(tracker.plan + (u_s - tracker.u_s), -1.0, 1.0)
        tracker.u_s, tracker.x_s = u_s, np.asarray(x_s, dtype=float)
        tracker._guess = None
        if self.y_ref is not None:   # the request under the new disturbances: said, if lost
            why = self._unreachable(self.y_ref, kernel)
            if why:
                self._moved_note = (f"at {measured or 'the measured disturbances'}, the "
                                    f"{why}: tracked to the closest reachable steady output")

    def restart(self) -> None:
        """Start the artificial steady state again at the next step, from the equilibrium
        of the current output estimate (as at the first step): after a measured disturbance
        moved the steady states so far that the shifted plan is no longer feasible."""
        self.tracker.u_s = None
        self.restarts += 1

    def _watch_target(self, r: np.ndarray, d_hat: np.ndarray, t: float) -> None:
        """Note the steps whose target ``r = ȳ − d̂`` (the steady output the model must
        reach for the plant to show ``ȳ``) lies outside ``Y_s`` (shifted by ``d̂`` when
        uncertified): the law then settles at the closest admissible steady state, a static
        offset no filter removes (docs: design/tracking.md, "The plants' own choices")."""
        fh = self.fhocp
        ys = fh.reference.ys_bounds
        limit = ys if self.certified else ys - fh.L @ d_hat
        if not np.max(fh.L @ r - limit) > TARGET_TOL:
            return
        seen = self.outside.setdefault(self.setpoint_changes, {"from": t, "steps": 0})
        seen.update(steps=seen["steps"] + 1, r=r.copy(), d_hat=d_hat.copy(), y_ref=self.y_ref)

    def notes(self) -> list[str]:
        """One line per set-point whose target left ``Y_s`` (:meth:`_watch_target`) and per
        set-point the measured disturbances left unreachable (:meth:`disturbance_moved`), in
        the problem's names and units: what the run's end prints."""
        model, names = self.model, self.model.problem.output_names
        units = self.model.problem.output_units
        out = []
        ys = steady_outputs_text(model, self.fhocp) or "none"
        for seen in list(self.outside.values())[:MAX_NOTES]:
            head = f"from t = {seen['from']:g} s the {setpoint_text(model, seen['y_ref'])}"
            tail = (f" on {seen['steps']} steps: tracked to the closest admissible steady "
                    "output, a static offset")
            if not self.certified:   # Y_s is around y + d̂: the set-point itself is outside
                out.append(f"{head} is outside the admissible steady outputs ({ys}){tail}")
                continue
            needed = model.denormalize_y(seen["r"])
            d = seen["d_hat"] * np.abs(model.y_scale)
            out.append(
                f"{head} needs the model's steady output at " + ", ".join(
                    f"{n}={v:.4g} {u}".rstrip() for n, v, u in zip(names, needed, units,
                                                                    strict=True))
                + " (disturbance estimate " + ", ".join(
                    f"{n} {v:+.3g} {u}".rstrip() for n, v, u in zip(names, d, units,
                                                                    strict=True))
                + f"), outside the certified steady outputs ({ys}){tail}")
        return out + self.moved_notes

    def setpoint_reason(self, y: np.ndarray) -> str:
        fh = self.fhocp
        if np.any(fh.L @ y > fh.reference.ys_bounds + 1e-12):
            return (f"{setpoint_text(self.model, y)} is outside the certified steady outputs "
                    f"({steady_outputs_text(self.model, fh) or 'none'})")
        return ""

    def uncertified(self, cert: Any, reason: str) -> TrackingLaw:
        from controllers.certification.grade import NotUsable, margin_text

        design = self.design
        cert_u, tracker, disturbance, _ = tracking_design(self.model, cert, design,
                                                          gains_certified=False, cert=cert,
                                                          measured=True)
        h = tracker.hypotheses
        if not h["Ys_nonempty"]:
            given = design["alpha_c"]
            raise NotUsable(
                self.component,
                f"{reason}, and even the model's measured prediction error "
                f"({margin_text(self.model, cert_u)}) leaves no admissible output in the box"
                + (f" with alpha_c = {given:g}; fix: a smaller alpha_c" if given is not None
                   else ": the model is too far from the plant to control it; fix: train it "
                   "longer or on more data"))
        if h["grid_points_admissible"] == 0:   # admissible outputs, maybe none of them steady
            unreachable = self._unreachable(h["Ys_centre"])
            if unreachable:
                raise NotUsable(
                    self.component,
                    f"{reason}, and none of the model's steady states at {h['grid_points']} "
                    "steady inputs across the input box has its output in the box tightened "
                    f"by its measured prediction error ({margin_text(self.model, cert_u)}), "
                    f"nor does one reach the middle of it ({unreachable}): it cannot be "
                    "steered to any output the constraints allow; fix: train it longer or on "
                    "more data, or widen the output box if the plant allows it")
        return TrackingLaw(self.model, cert_u, tracker, disturbance, design, self.component,
                           certified=False)

    def _unreachable(self, y: Any, kernel: Any = None) -> str:
        """Why no steady state of the model has the output ``y`` (normalised) with its inputs
        in the box (the equilibrium search's words, physical units; ``kernel``: the compiled
        search, the step's); ``""`` when one has."""
        from controllers.equilibrium import equilibrium
        from controllers.errors import SetpointError

        if y is None:
            return "no admissible output"
        try:
            equilibrium(self.model, np.asarray(y, dtype=float), kernel)
        except SetpointError as exc:
            return str(exc)
        return ""

    def settings(self) -> list[Setting]:
        fh, pr = self.fhocp, self.model.problem
        return settings_of(self.disturbance.beta, fh.R, fh.du_weight if fh.has_du else None,
                           self._offset_weights, list(pr.input_names),
                           list(pr.output_names))

    def refuse(self, name: str, value: float) -> str:
        shared = refuse_shared(name, value, self.fhocp.R, list(self.model.problem.input_names))
        if shared is not None:
            return shared
        return refuse_weight(value, positive=name.startswith("offset_weight."))

    def set(self, name: str, value: float) -> str:
        family, _, signal = name.partition(".")
        pr = self.model.problem
        if family == "offset_filter":
            self.disturbance.beta = float(value)
            return "the output-disturbance estimate's gain"
        if family == "offset_weight":
            a = pr.output_names.index(signal)
            self._offset_weights[a] = float(value)
            if self.controlled[a]:   # an output not controlled keeps T = 0 until it returns
                self.fhocp.set_weight("T", a, float(value))
            return "the offset cost (the tracking law's hypotheses hold for any T > 0)"
        self.fhocp.set_weight("R" if family == "R" else "du", pr.input_names.index(signal),
                              float(value))
        return ("the FHOCP's input cost (the tracking law's hypotheses hold for any R > 0, "
                "S >= 0)")

    def applied(self, u: np.ndarray) -> None:
        self.tracker.u_prev = np.array(u, dtype=float)

    def control(self, controlled: np.ndarray) -> str:
        """An output not controlled leaves the offset cost (its weight ``T`` 0, the
        engineer's kept for its return); its rows, and ``Y_s``'s, stay."""
        fh, names = self.fhocp, self.model.problem.output_names
        for a, keep in enumerate(controlled):
            fh.set_weight("T", a, float(self._offset_weights[a]) if keep else 0.0)
        self.controlled = np.array(controlled, dtype=bool)
        dropped = [n for n, c in zip(names, self.controlled, strict=True) if not c]
        return ("the offset cost without " + ", ".join(dropped) if dropped
                else "every output in the offset cost")

    def summary(self) -> dict[str, Any]:
        fh = self.fhocp
        return {"alpha_c": fh.reference.alpha_c, "control_horizon": fh.reference.control_horizon,
                "offset_weight": {n: float(w) for n, w in zip(
                    self.model.problem.output_names, fh.reference.offset_weight, strict=True)},
                "offset_filter": self.disturbance.beta,
                "tracking_hypotheses": self.tracker.hypotheses,
                "offset_free": False, "setpoint_rate": None, "governor": False,
                "governor_steps": 0, "governor_holds": 0,
                "setpoint_changes": self.setpoint_changes, "setpoint_rejected_steps": 0,
                "setpoint_rejections": [],
                "target_outside_Ys_steps": sum(v["steps"] for v in self.outside.values()),
                "steady_state_restarts": self.restarts,
                "notes": self.notes()}


def steady_outputs_text(model: Any, fhocp: Any) -> str:
    """The admissible steady outputs ``Y_s`` of a box problem, per output, in its units."""
    problem = model.problem
    parts = []
    for j, name in enumerate(problem.output_names):
        hi = lo = None
        for row, rhs in zip(fhocp.L, fhocp.reference.ys_bounds, strict=True):
            if row[j] > 0 and np.count_nonzero(row) == 1:
                hi = rhs / row[j]
            elif row[j] < 0 and np.count_nonzero(row) == 1:
                lo = rhs / row[j]
        if lo is None or hi is None:
            continue
        a, b = sorted(model.denormalize_y(np.full(model.p, v))[j] for v in (lo, hi))
        unit = problem.output_units[j]
        parts.append(f"{name} in [{a:.4g}, {b:.4g}] {unit}".rstrip() if a <= b
                     else f"{name}: none")
    return "; ".join(parts)
