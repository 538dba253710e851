"""The robust GRU MPC of the paper (Fig. 1: observer + FHOCP), one controller with one step.

:class:`RobustMPC` reads the measured outputs of its control problem
(:class:`controllers.problem.ControlProblem`, the model file's), their set-points and the
measured disturbances, and gives the inputs to apply, all in the problem's units
(:meth:`RobustMPC.step`); internally it works in the model file's normalised units. It owns
its parts:

- the observer ``eq:observer`` (:class:`controllers.observer.GRUObserver`), which advances
  ``x̂`` with the last input and the measured output, and ``ê_o`` by ``eq:eo-evolution``;
  ``x̂_0`` is the model equilibrium for the first measured output (paper section V);
- the held inputs (:class:`controllers.held_inputs.HeldInputs`): the measured disturbances
  held in the design model's biases and the dead time predicted over;
- the control law (:class:`controllers.laws.base.ControlLaw`), built by the law's spec from
  the design (:class:`controllers.mpc_options.MPCOptions`, :mod:`controllers.laws`): the
  tracking law (default) or the paper's law ``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``);
- its grade (:mod:`controllers.certification.grade`): certified, or uncertified with the
  model's measured prediction error as the tightening.

What may change between steps goes through one setter, :meth:`RobustMPC.set` (its names:
:meth:`RobustMPC.settings`), which checks the value against the design and says what it
re-derived; the exported controller's tunable parameters are the same settings
(:mod:`controllers.kernel.controller_source`). The co-simulation binds this object as a
component (:class:`cosim.adapters.robust_mpc.RobustMPCController`); the C step of the
controller FMU does the same step to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.errors import ControllersError, DesignError, OptionError, StepInputError
from controllers.mpc_options import MPCOptions, design_arguments, plain
from controllers.ocp.solve_status import status_code

__all__ = ["RobustMPC", "Step"]


@dataclass
class Step:
    """What one step gave: the inputs to apply ``u`` (the problem's units, inside their
    box), the law's step record (:class:`controllers.laws.base.StepRecord`: the solve, the
    plan, whether the fallback was applied) and the diagnostics by name (the problem's
    units)."""

    u: np.ndarray
    record: Any
    diagnostics: dict[str, float] = field(default_factory=dict)
    #: what the law computed (problem units; the operator's settings may give the plant
    #: other inputs, :mod:`controllers.mpc_operating`): ``u`` itself when they do not
    computed: np.ndarray | None = None


class RobustMPC:
    """The robust MPC (module docstring).

    Parameters
    ----------
    model : GRUModel
        The model, with its control problem (``model.problem``).
    options : MPCOptions
        The design (defaults filled in).
    name : str
        How messages name the controller.
    """

    def __init__(self, model: Any, options: MPCOptions, name: str = "mpc") -> None:
        from controllers.certification.grade import Certification, go_uncertified
        from controllers.held_inputs import HeldInputs
        from controllers.observer import GRUObserver

        self.name = name
        self.problem = model.problem
        #: the model as trained (inputs and measured disturbances); :attr:`model` holds the
        #: disturbances in its biases (:attr:`held`)
        self.full_model = model
        #: the measured disturbances and dead time (:class:`~controllers.held_inputs.
        #: HeldInputs`)
        self.held = HeldInputs(name, model)
        self.model = self.held.model
        #: the design (:class:`controllers.mpc_options.MPCOptions`, defaults filled in)
        self.options = options
        law, failed = self._design(options)
        self.law = law
        # load scipy.optimize (the observer's x̂_0 equilibrium) now, so that the first
        # control step is a normal one (importing scipy.optimize: ~0.2 s)
        import scipy.optimize  # noqa: F401

        self.observer = GRUObserver.from_certificate(self.cert)
        self.u_lo = np.array([c.min for c in self.problem.inputs])
        self.u_hi = np.array([c.max for c in self.problem.inputs])
        #: The observer's initial state ``x̂_0`` (normalised), or ``None``: the equilibrium for
        #: the first measured output (paper section V). Read by :meth:`reset`.
        self.initial_estimate: np.ndarray | None = None
        #: certified, or uncertified with the reason (:mod:`controllers.certification.grade`)
        self.certification = Certification()
        self._expected: list[dict[str, float]] | None = None
        if failed:
            go_uncertified(self, "; ".join(failed))
        from controllers.mpc_operating import Operating

        #: the operator's settings and what they re-derive (:mod:`controllers.mpc_operating`)
        self.operating = Operating(self)
        self.reset()

    def _design(self, o: MPCOptions) -> tuple[Any, list[str]]:
        """The law of the options ``o`` on this model, and the hypotheses that fail: the
        observer gains (the model file's, ``gain_scale``, else the largest scale that passes
        at :func:`controllers.certification.gain_design.default_setpoints`), then the law's
        spec builds it (:mod:`controllers.laws`)."""
        from controllers.certification import certificates as certs
        from controllers.certification import gain_design
        from controllers.laws.base import LawContext
        from controllers.ocp.input_rate import du_weights, move_limit

        inputs = list(self.problem.input_names)
        try:
            self.du_weight = du_weights(o.du_weight, len(inputs), inputs)
        except ControllersError as exc:
            raise OptionError(f"option {exc}") from None
        kwargs = design_arguments(o, self.model)
        gains_certified = True
        if o.gain_scale is None and self.model.L_z is None:
            targets = [self.model.normalize_y(np.array(y))
                       for y in gain_design.default_setpoints(self.problem)]
            theta, cert = gain_design.choose_gain_scale(self.model, targets, **kwargs)
            if theta is None:
                gains_certified = False
                cert = certs.compute_certificate(self.model, gain_scale=0.0, **kwargs)
        else:
            cert = certs.compute_certificate(self.model, gain_scale=o.gain_scale, **kwargs)
        fhocp_options: dict[str, Any] = dict(
            solver=o.solver, sqp_options={"max_iter": o.max_iter}, kernel=o.kernel,
            du_weight=self.du_weight, soft=not o.hard_constraints,
            max_move=move_limit([c.max_move for c in self.problem.inputs], self.problem.inputs),
            ipopt_options={"max_iter": o.max_iter, **(o.ipopt_options or {})}
            if o.ipopt_options or o.solver == "ipopt" else None)
        context = LawContext(self.model, cert, gains_certified, o, kwargs, fhocp_options,
                             self.name)
        return o.spec.hook("law", "build")(context)

    # -- what the law holds ----------------------------------------------------------------
    @property
    def law(self) -> Any:
        """The control law (:class:`controllers.laws.base.ControlLaw`)."""
        return self._law

    @law.setter
    def law(self, law: Any) -> None:
        """Every law this controller runs, the design's and the uncertified one that may
        replace it (:func:`controllers.certification.grade.go_uncertified`), predicts with the
        inputs already applied (:attr:`held`'s prefix: the dead times beyond the shortest);
        an FHOCP without them applied its first stage of every input, which the plant sees
        ``e_j`` samples later than the plan has it."""
        try:
            law.fhocp.use_prefix(self.held.prefix)
        except ControllersError as exc:
            raise DesignError(f"controller {self.name!r}: problem {self.problem.name!r}: "
                              f"{exc}") from None
        self._law = law

    @property
    def fhocp(self) -> Any:
        """The law's optimal-control problem."""
        return self.law.fhocp

    @property
    def cert(self) -> Any:
        """The certificate the law's tightening comes from."""
        return self.law.cert

    @property
    def certificate_mode(self) -> str:
        """The option ``certificate``: ``"auto"``, ``"require"`` or ``"keep"``."""
        return self.options.certificate

    @property
    def notice(self) -> str | None:
        """The one line to show before a run (why it runs uncertified), else ``None``."""
        return self.certification.notice

    @property
    def previewed(self) -> tuple[str, ...]:
        """The measured disturbances known ahead (``preview = true``)."""
        return tuple(c.name for c in self.problem.disturbances if c.preview)

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """Check the run's set-points (by output name, the problem's units) against the
        certified design; the first outside it makes the run uncertified (refused with
        ``certificate="require"``, ignored with ``"keep"``)."""
        from controllers.certification.grade import check_setpoints, go_uncertified

        if setpoints == self._expected:
            return
        self._expected = [dict(sp) for sp in setpoints]
        if self.certification.certified and self.certificate_mode != "keep":
            reason = check_setpoints(self, setpoints)
            if reason:
                go_uncertified(self, reason)

    # -- a run -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the run: the observer (at :attr:`initial_estimate`, else the model
        equilibrium for the first measured output), the held inputs, the law and its
        statistics.

        The FHOCP's solver is built anew (3 ms): the QP solver keeps state between solves,
        so a controller reused for another run gives exactly the results of a new one.
        """
        x0 = None if self.initial_estimate is None else np.asarray(self.initial_estimate,
                                                                    dtype=float)
        self.observer.reset(x0=x0, e_o0=self.cert.e_o0)
        self.held.reset()   # the kernel is built (and found) for the nominal biases
        for name, value in getattr(self, "_design_values", {}).items():
            self.law.set(name, value)   # a run starts from the design's settings
        #: the design's values of the settings changed in this run (:meth:`set`)
        self._design_values: dict[str, float] = {}
        #: when the controller first fell back on the candidate (``None``: never)
        self.first_fallback_t: float | None = None
        self.fhocp.setup()
        self.observer.kernel = self.fhocp.kernel   # its compiled GRU step (same model)
        self.law.reset()
        self.operating.reset()

    def set_schedule(self, schedule: Mapping[str, Callable[[float], float]] | None) -> None:
        """The values to come of :attr:`previewed`, for this run (after :meth:`reset`):
        ``schedule[name](t)``, as set on the plant at ``t`` (the problem's units); without
        one they are held at their measured value (``preview_held_steps`` in the
        summary)."""
        self.held.set_schedule(schedule)

    def step(self, y: np.ndarray, ref: np.ndarray, d: np.ndarray | None, t: float) -> Step:
        """``u_k`` from the measured outputs ``y``, their set-points ``ref`` and the measured
        disturbances ``d`` (the problem's units, in its order) at ``t``; the observer
        advances.

        Raises
        ------
        StepInputError
            A measured output, set-point or disturbance that is not finite.
        """
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(ref))):
            names = [*self.problem.output_names, *(f"ref.{n}" for n in self.problem.output_names)]
            values = ", ".join(f"{n}={v:g}" for n, v in zip(names, [*y, *ref], strict=True))
            raise StepInputError(f"controller {self.name!r}: non-finite input at t={t:g} s "
                                 f"({values})")
        model, held, law, observer = self.model, self.held, self.law, self.observer
        yn = model.normalize_y(y)
        y_ref = model.normalize_y(ref)
        if held.shift is not None:
            moved = held.measure(d, t, self.fhocp)
            if moved:
                law.disturbance_moved(moved)
        if observer.x_hat is None:
            observer.init_from_output(yn)
        operating = self.operating
        engaged = operating.operator.engaged
        if engaged or self.fhocp.operator is not None:
            ref = operating.before(ref, t)
            y_ref = model.normalize_y(ref)
        e_o = observer.e_o
        x_start = held.ahead(observer, self.fhocp)
        x0 = np.array(observer.x_hat if x_start is None else x_start, dtype=float)
        step = (law.step(observer, yn, y_ref, t) if x_start is None
                else law.step(observer, yn, y_ref, t, x_start=x_start))
        rec = step.record
        if held.shift is not None and rec.fallback and not rec.candidate_feasible:
            # a measured disturbance moved the steady states beyond the plan: start again
            # from the equilibrium of the output estimate at the disturbance now measured
            law.restart()
        if rec.fallback and self.first_fallback_t is None:
            self.first_fallback_t = float(t)
        computed = np.clip(model.denormalize_u(rec.u), self.u_lo, self.u_hi)
        u, un = computed, rec.u
        if engaged:   # the plant's inputs: the operator's, held, limited
            u, un = operating.after(rec.u)
        else:
            operating.operator.last = computed
        observer.make_step(held.model_input(un, self.fhocp), yn)
        held.applied(un)
        out = Step(u, rec, self._diagnostics(step, e_o), computed)
        operating.record(out, y, un, x0, t)
        return out

    def _diagnostics(self, step: Any, e_o: float) -> dict[str, float]:
        """One step's diagnostics (the law's own last)."""
        rec = step.record
        res = rec.result
        return {
            "solve_ms": res.solve_time * 1e3,
            "iterations": float(res.iterations),
            "status": float(status_code(res.status)),
            "cost": float(res.cost) if math.isfinite(res.cost) else float("nan"),
            "alpha": self.law.alpha,
            "e_o": e_o,
            "x_hat_error_bound": e_o,
            "active_constraints": float(res.active),
            "softened": float(res.softened),
            "fallback": float(rec.fallback),
            "suboptimal": float(rec.suboptimal),
            "setpoint_rejected": float(step.rejected),
            "governor_lambda": step.governor_lambda,
            **step.diagnostics,
        }

    # -- settings between steps --------------------------------------------------------------
    def settings(self) -> list[Any]:
        """What :meth:`set` takes, with the values now: the law's settings
        (:meth:`controllers.laws.base.ControlLaw.settings`), which are the exported
        controller's tunable parameters of the same names and order."""
        return self.law.settings()

    def set(self, name: str, value: float) -> str:
        """Setting ``name`` from the next step on, checked against the design (a weight that
        keeps ``R`` positive definite, a gain in (0, 1], ...); what was re-derived, in one
        line. The setting holds for the run: :meth:`reset` restores the design's.

        Raises
        ------
        OptionError
            An unknown setting, or a value the design cannot take (nothing changes).
        """
        known = {s[0]: s for s in self.law.settings()}
        if name not in known:
            raise OptionError(f"controller {self.name!r}: no setting {name!r} (settings: "
                              f"{', '.join(known)})")
        value = float(value)
        why = self.law.refuse(name, value)
        if why:
            raise OptionError(f"controller {self.name!r}: setting {name}={value!r}: {why}")
        self._design_values.setdefault(name, known[name][4])
        return f"{name} = {value:g}: {self.law.set(name, value)}"

    def operator_settings(self) -> list[Any]:
        """The operator's settings (:meth:`controllers.operator.Operator.settings`): mode,
        inputs in service and in manual, outputs controlled, operator limits."""
        return self.operating.operator.settings()

    def operate(self, name: str, value: float) -> str:
        """Operator setting ``name`` (``op.*``) from the next step on, checked against the
        design and the certificate (:meth:`controllers.mpc_operating.Operating.operate`);
        what it re-derived, in one line. The settings hold for the run: :meth:`reset`
        restores auto with the engineer's box.

        Raises
        ------
        OptionError
            A value refused in the user's words (nothing changes).
        """
        return self.operating.operate(name, value)

    def export_design(self) -> Any:
        """The numbers of its step in C (:meth:`controllers.kernel.controller_source.
        ControllerDesign.of`: the exported controller FMU's), its FHOCP set up."""
        from controllers.kernel.controller_source import ControllerDesign

        return ControllerDesign.of(self.law, self.observer, self.model, self.u_lo, self.u_hi)

    def summary(self) -> dict[str, Any]:
        """The run's statistics and the design (``summary.json``'s controller part)."""
        from controllers.laws.base import solver_summary

        out = solver_summary(self.law.records)
        out.update(self.certification.summary())
        out.update({
            "law": self.law.name,
            "problem": self.problem.name,
            "N": self.fhocp.N,
            "formulation": self.fhocp.formulation,
            "kernel": "compiled" if self.fhocp.kernel is not None else "numpy",
            "du_weight": {n: float(w) for n, w in zip(self.problem.input_names,
                                                      self.du_weight, strict=True)},
            "gain_scale": self.cert.gain_scale,
            **self.held.summary(),
            **self.law.summary(),
            "options": plain(self.options.to_dict()),
        })
        operating = self.operating.summary()
        out["operator"] = operating
        if operating["notes"]:
            out["notes"] = [*out.get("notes", []), *operating["notes"]]
        if out.get("fallbacks"):
            out["shortfall"] = self._shortfall(out)
        return out

    def _shortfall(self, stats: dict[str, Any]) -> dict[str, Any]:
        """The steps the controller did not serve (``summary.json``'s ``shortfall``, which
        the run's verdict reads: :func:`cosim.core.run_result.shortfall_verdict`): how many
        of how many, why (the solves' statuses, most frequent first) and when first."""
        why = sorted(stats.get("failures_by_status", {}).items(), key=lambda kv: -kv[1])
        return {"steps": int(stats["fallbacks"]), "of": int(stats["steps"]),
                "what": "fell back on the candidate plan",
                "why": ", ".join(f"{status} {count}" for status, count in why[:3]),
                "first_time": self.first_fallback_t}

