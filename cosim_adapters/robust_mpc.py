"""The robust GRU MPC of the paper (Fig. 1: observer + FHOCP) as a co-simulation component.

``RobustMPCController`` reads the measured outputs of its control problem (the model file's,
:class:`controllers.problem.ControlProblem`) and their set-points ``ref.<output>``, and writes
its inputs, all in the problem's units (for the four-tank: levels ``h1``, ``h2`` in metres,
pump flows ``qa``, ``qb`` in m³/s). Internally it works in the model file's normalised
units. Each step the observer ``eq:observer`` (:class:`controllers.observer.GRUObserver`)
advances ``x̂`` with the last input and the measured output, and ``ê_o`` by
``eq:eo-evolution``; ``x̂_0`` is the model equilibrium for the first measured output (paper
section V). Then one of two control laws (option ``law``) gives ``u_k``:

- ``"tracking"`` (the default): the tracking law of :mod:`cosim_adapters.tracking`, the
  tracking FHOCP of :mod:`controllers.ocp.reference_tracking` (an artificial steady state as a
  decision variable, offset-free through the disturbance estimate ``d̂`` in the cost, the
  input-rate terms of ``du_weight``); every set-point is accepted, and an unreachable or
  inadmissible one is tracked to the closest admissible steady state (docs:
  design/tracking.md).
- ``"paper"``: the paper's law, with its set-point handling in :mod:`cosim_adapters.paper_law`:
  when ``ȳ`` changes, the equilibrium ``(x̄, ū)`` and ``α`` (``eq:def-alpha``) via
  :meth:`controllers.certification.certificates.Certificate.reference`, which also checks
  Assumption 1 (``ass:setpoint``) and ``eq:condition-recursive-feasibility``; then
  ``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``, :class:`controllers.ocp.paper_mpc.RobustMPC`: the
  FHOCP ``eq:optimization`` with the shifted-candidate fallback).

Measured disturbances (the problem's ``[disturbances]``, controller inputs ``dist.<name>``)
and dead time (``delay``): the design's model holds the disturbances in its biases, moved to
the measured value each step, and ``x̂`` is predicted over the dead time before the FHOCP
starts (:class:`cosim_adapters.held_inputs.HeldInputs`). Both laws compute their equilibria
under the disturbances held (the paper's law its reference ``(x̄, ū, α)`` again when they
move, :meth:`cosim_adapters.paper_law.PaperLaw.disturbance_moved`) and start their FHOCP
from ``x̂`` predicted over the dead time.

Any numbers of inputs ``m`` and outputs ``p`` (the problem's). With more outputs than inputs
(``p > m``) only set-points on the model's ``m``-dimensional surface of equilibrium outputs
are reachable: the tracking law steers to the closest one, the paper's law refuses the
others like any unreachable set-point, naming the closest reachable equilibrium output.

The paper's law and set-points outside its theory (unreachable, or failing Assumption 1 /
eq. 11): the controller keeps regulating to the last admissible set-point, counts the step in
``setpoint_rejected`` (diagnostics and summary) and names the failed hypothesis (or, for an
unreachable one, the closest reachable equilibrium output) in the summary. A first set-point
that is already inadmissible is a configuration error (:class:`cosim.core.errors.CosimError`, the
same reason). Its set-point changes go through the admissible reference governor of
:mod:`controllers.ocp.governor` (on by default, ``governor=False`` gives the paper's controller,
which switches ``(x̄, ū, α)`` at once): the set-point handed to the FHOCP moves towards the
requested one only as far as a sequence known to be feasible exists, by at most a fraction
``λ_max`` of the way that halves after a solve that did not converge and doubles after one
that did; that sequence is the solver's initial guess and the fallback. Under the paper's
law ``du_weight`` (off by default) adds the input-rate penalty ``Σ_i (u_i − u_{i−1})ᵀ S (u_i
− u_{i−1})`` (normalised units, ``u_{−1}`` the input applied at the previous step;
:mod:`controllers.ocp.input_rate`), outside the paper's cost, and ``offset_free=True`` (outside
the theorem) shifts the model set-point by a filtered estimate ``d̂`` of the output mismatch
``y − ŷ`` (``ȳ_model = ȳ − d̂``); the shifted set-point must still pass the checks.

This module is the co-simulation adapter (a :class:`cosim.core.component.Component`) of the
numerical core: the core modules know nothing of ``cosim``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from controllers.errors import ControllersError
from controllers.model import DEFAULT_MODEL
from controllers.ocp.solve_status import status_code
from cosim.core.component import Capability, Component, Signal
from cosim.core.errors import CosimError
from cosim_adapters.certification import Certification, check_setpoints, go_uncertified
from cosim_adapters.law import ControlLaw
from cosim_adapters.mpc_options import MPCOptions
from cosim_adapters.paper_law import PaperLaw, SetpointHandling
from cosim_adapters.tracking import TrackingLaw

__all__ = ["RobustMPCController", "design_arguments"]


def _plain(value: Any) -> Any:
    """``value`` as JSON data (arrays as nested lists, mappings as objects)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray | list | tuple):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def _weight(key: str, value: Any, size: int, names: list[str] | None) -> np.ndarray | None:
    """A cost weight option as a matrix: ``None`` (the default), a number (times the
    identity), an object by signal name (diagonal; ``names`` given) or a matrix."""
    if value is None:
        return None
    given = value
    if isinstance(value, Mapping) and names is not None:
        unknown = sorted(set(value) - set(names))
        if unknown:
            raise CosimError(f"option {key}: {unknown[0]!r} is not one of {', '.join(names)}")
        value = np.diag([float(value.get(n, 0.01)) for n in names])
    try:
        w = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CosimError(f"option {key}={value!r}: expected a number, a {size}x{size} matrix"
                         + (" or an object by input name" if names else "")) from None
    if w.ndim == 0:
        w = float(w) * np.eye(size)
    if w.shape != (size, size):
        raise CosimError(f"option {key}: expected a number or a {size}x{size} matrix, got "
                         f"shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise CosimError(f"option {key}={_plain(given)!r}: expected finite numbers")
    return w


#: ``Q="outputs"``: the stage cost on the model's outputs, ``Q = U_oᵀ U_o + ε I`` (ε keeps Q
#: positive definite, as the theorem needs, and the hidden states all but free).
OUTPUT_WEIGHT_EPS = 1e-3


def _state_weight(value: Any, params: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The state weight ``Q``: :func:`_weight`, or ``"outputs"``: ``U_oᵀ U_o + ε I``
    (:data:`OUTPUT_WEIGHT_EPS`), the outputs' tracking error rather than every hidden
    state's distance to the reference."""
    n = params["U_o"].shape[1]
    if isinstance(value, str):
        if value != "outputs":
            raise CosimError(f"option Q={value!r}: expected a number, a {n}x{n} matrix or "
                             "\"outputs\"")
        Uo = np.asarray(params["U_o"], dtype=float)
        return Uo.T @ Uo + OUTPUT_WEIGHT_EPS * np.eye(n)
    return _weight("Q", value, n, None)


def design_arguments(o: MPCOptions, model: Any) -> dict[str, Any]:
    """The certificate's design arguments of the options ``o`` on ``model`` (its problem's
    inputs): ``N``, ``Q`` (``"outputs"`` built from its ``U_o``), ``R`` (an object by input
    name as a diagonal) and ``e_o0``; what the controller and ``cosim certify`` compute the
    certificate (:func:`controllers.certification.certificates.compute_certificate`) with."""
    inputs = list(model.problem.input_names)
    return {"N": o.N, "Q": _state_weight(o.Q, model.params),
            "R": _weight("R", o.R, len(inputs), inputs), "e_o0": o.e_o0}


class RobustMPCController(Component):
    """Robust MPC with GRU model and observer (Schimperna & Magni), normalised internally.

    Parameters
    ----------
    model : str or Path, optional
        Model file (default: the shipped ``controllers/models/fourtank_gru.json``).
    problem : str or Path, optional
        A problem file: must be the model's own (a check; its ``[mpc]`` table, the tuning,
        may differ and, when it has one, is the one used), or the problem of a model file
        that has none (:mod:`cosim_adapters.problems`).
    options : MPCOptions or mapping, optional
        The design (:class:`cosim_adapters.mpc_options.MPCOptions`), as an object (used as
        it is) or by key (over the problem's ``[mpc]`` table,
        :meth:`~cosim_adapters.mpc_options.MPCOptions.resolve`).
    name : str
        Component name.
    **option_values
        Options by name (the attributes of :class:`~cosim_adapters.mpc_options.MPCOptions`,
        which say what each one does), over ``options``.
    """

    direct_feedthrough = True
    capabilities = frozenset({Capability.SETPOINTS, Capability.DISTURBANCES,
                              Capability.PREVIEW, Capability.NOTICE})
    #: the options :func:`cosim.core.registry.create` accepts (``--option KEY=VALUE``)
    OPTIONS = ("model", "problem", "options", "name", *MPCOptions.names())
    #: wall-clock diagnostics: written by the master to timings.csv, not results.csv
    timing_diagnostics = frozenset({"solve_ms"})

    def __init__(self, model: str | Path | None = None, problem: str | Path | None = None,
                 options: MPCOptions | Mapping[str, Any] | None = None, *,
                 name: str = "mpc", **option_values: Any) -> None:
        from controllers.model import GRUModel
        from controllers.observer import GRUObserver
        from cosim_adapters.problems import problem_for

        if not isinstance(name, str) or not name:
            raise CosimError(f"option name={name!r}: expected a non-empty string")
        self.name = name
        self.model_path = Path(model) if model is not None else DEFAULT_MODEL
        try:
            self.model = GRUModel.load(self.model_path)
        except ControllersError as exc:
            raise CosimError(str(exc)) from None
        self.problem = problem_for(self.model, problem)
        self.model.problem = self.problem
        #: the model as trained (inputs and measured disturbances); :attr:`model` holds the
        #: disturbances in its biases (:attr:`held`)
        self.full_model = self.model
        if not isinstance(options, MPCOptions):
            options = MPCOptions.resolve({**(options or {}), **option_values}, self.problem)
        elif option_values:
            options = MPCOptions.from_mapping({**options.to_dict(), **option_values})
        from cosim_adapters.held_inputs import HeldInputs

        #: the measured disturbances and dead time (:class:`~cosim_adapters.held_inputs.
        #: HeldInputs`)
        self.held = HeldInputs(self.name, self.full_model)
        self.model = self.held.model
        #: the design (:class:`cosim_adapters.mpc_options.MPCOptions`, defaults filled in;
        #: the problem's ``[mpc]`` under the options given, :meth:`MPCOptions.resolve`)
        self.options = options
        #: the control law (:class:`cosim_adapters.law.ControlLaw`): everything that differs
        #: between ``law="tracking"`` and ``law="paper"``
        self.law: ControlLaw
        self.law, failed = self._design(options)
        try:
            self.fhocp.use_prefix(self.held.prefix)
        except ControllersError as exc:
            raise CosimError(f"controller {self.name!r}: problem {self.problem.name!r}: "
                             f"{exc}") from None
        # load scipy.optimize (the observer's x̂_0 equilibrium) now, so that the first
        # control step is a normal one (importing scipy.optimize: ~0.2 s)
        import scipy.optimize  # noqa: F401

        self.observer = GRUObserver.from_certificate(self.cert)
        self._signals()
        #: The observer's initial state ``x̂_0`` (normalised), or ``None``: the equilibrium for
        #: the first measured output (paper section V). Read by :meth:`setup`.
        self.initial_estimate: np.ndarray | None = None
        #: certified, or uncertified with the reason (:mod:`cosim_adapters.certification`)
        self.certification = Certification()
        self._expected: list[dict[str, float]] | None = None
        if failed:
            go_uncertified(self, "; ".join(failed))
        self.setup(0.0)

    def _design(self, o: MPCOptions) -> tuple[ControlLaw, list[str]]:
        """The law of the options ``o`` on this model, and the hypotheses that fail: the
        observer gains (the model file's, ``gain_scale``, else the largest scale that passes
        at :func:`controllers.certification.gain_design.default_setpoints`) and the law's design."""
        from controllers.certification import certificates as certs
        from controllers.certification import gain_design
        from controllers.ocp.input_rate import du_weights

        inputs = list(self.problem.input_names)
        try:
            self.du_weight = du_weights(o.du_weight, len(inputs), inputs)
        except ControllersError as exc:
            raise CosimError(f"option {exc}") from None
        kwargs = design_arguments(o, self.model)
        gains_certified = True
        try:
            if o.gain_scale is None and self.model.L_z is None:
                targets = [self.model.normalize_y(np.array(y))
                           for y in gain_design.default_setpoints(self.problem)]
                theta, cert = gain_design.choose_gain_scale(self.model, targets, **kwargs)
                if theta is None:
                    gains_certified = False
                    cert = certs.compute_certificate(self.model, gain_scale=0.0, **kwargs)
            else:
                cert = certs.compute_certificate(self.model, gain_scale=o.gain_scale, **kwargs)
        except ControllersError as exc:  # a bad design or a model without certificate
            raise CosimError(str(exc)) from None
        fhocp_options: dict[str, Any] = dict(
            solver=o.solver, sqp_options={"max_iter": o.max_iter}, kernel=o.kernel,
            du_weight=self.du_weight,
            ipopt_options={"max_iter": o.max_iter, **(o.ipopt_options or {})}
            if o.ipopt_options or o.solver == "ipopt" else None)
        if o.tracking:
            design = {"kwargs": kwargs, "fhocp_options": fhocp_options,
                      "offset_weight": o.offset_weight, "alpha_c": o.alpha_c,
                      "offset_filter": o.offset_filter, "control_horizon": o.control_horizon}
            return TrackingLaw.build(self.model, cert, design, self.name, gains_certified)
        rate = None if o.setpoint_rate is None else float(o.setpoint_rate)
        handling = SetpointHandling(bool(o.governor), bool(o.offset_free),
                                    float(o.offset_filter), rate)
        law = PaperLaw(self.model, cert, fhocp_options, handling, name=self.name)
        return law, cert.failures()

    def _signals(self) -> None:
        """The component's signals, sample time and boxes, from the control problem."""
        pr = self.problem
        self._y_names = list(pr.output_names)
        self._r_names = [f"ref.{n}" for n in self._y_names]
        self._u_names = list(pr.input_names)
        self.inputs = tuple(Signal(c.name, c.unit, c.description or f"measured {c.name}")
                            for c in pr.outputs) + tuple(
            Signal(f"ref.{c.name}", c.unit, f"set-point of {c.name}") for c in pr.outputs)
        self.inputs += tuple(Signal(f"dist.{c.name}", c.unit, c.description
                                    or f"measured disturbance {c.name}")
                             for c in pr.disturbances)
        #: what a run without a ``dist.<name>`` column applies and measures: the nominal
        #: value (the middle of the box, or the normalisation's offset)
        self.disturbance_defaults = {c.name: c.offset for c in pr.disturbances}
        self.outputs = tuple(Signal(c.name, c.unit, c.description) for c in pr.inputs)
        self.sample_time = float(self.model.Ts)
        self.bounds = pr.bounds()
        self._lo = np.array([c.min for c in pr.inputs])
        self._hi = np.array([c.max for c in pr.inputs])
        self._values: dict[str, float] = {}

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

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """Check the run's set-points against the certified design; the first outside it
        makes the run uncertified (refused with ``certificate="require"``, ignored with
        ``"keep"``)."""
        if setpoints == self._expected:
            return
        self._expected = [dict(sp) for sp in setpoints]
        if self.certification.certified and self.certificate_mode != "keep":
            reason = check_setpoints(self, setpoints)
            if reason:
                go_uncertified(self, reason)

    # -- Component interface -----------------------------------------------------------
    def setup(self, t0: float) -> None:
        """Reset the observer, the MPC and all counters for a run starting at ``t0``.

        The FHOCP's solver is built anew (3 ms): the QP solver keeps state between solves,
        so a controller reused for another run gives exactly the results of a new one. The
        observer starts at :attr:`initial_estimate` when it is set, else at the model
        equilibrium for the first measured output.
        """
        x0 = None if self.initial_estimate is None else np.asarray(self.initial_estimate,
                                                                    dtype=float)
        self.observer.reset(x0=x0, e_o0=self.cert.e_o0)
        self.held.reset()   # the kernel is built (and found) for the nominal biases
        self.fhocp.setup()
        self.observer.kernel = self.fhocp.kernel   # its compiled GRU step (same model)
        self.law.reset()
        self._u_phys = 0.5 * (self._lo + self._hi)
        self._diag: dict[str, float] = {}

    @property
    def previewed(self) -> tuple[str, ...]:
        """The measured disturbances known ahead (``preview = true``): the master gives the
        run's schedule of each (:meth:`set_schedule`)."""
        return tuple(c.name for c in self.problem.disturbances if c.preview)

    def set_schedule(self, schedule: Mapping[str, Any] | None) -> None:
        """The values to come of :attr:`previewed`, for this run (after :meth:`setup`):
        ``schedule[name](t)``, as set on the plant at ``t`` (the problem's units); without
        one they are held at their measured value (``preview_held_steps`` in the
        summary)."""
        self.held.set_schedule(schedule)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._values.update({k: float(v) for k, v in values.items()})

    def get_outputs(self) -> dict[str, float]:
        return {n: float(u) for n, u in zip(self._u_names, self._u_phys, strict=True)}

    def step(self, t: float, dt: float) -> None:
        """Compute ``u_k`` from the measured outputs and the set-points at ``t``; advance the
        observer."""
        try:
            y_phys = np.array([self._values[n] for n in self._y_names])
            r_phys = np.array([self._values[n] for n in self._r_names])
        except KeyError as exc:
            raise CosimError(f"controller {self.name!r}: input {exc.args[0]!r} was never set "
                             f"(wire {', '.join(self._y_names + self._r_names)})") from None
        if not (np.all(np.isfinite(y_phys)) and np.all(np.isfinite(r_phys))):
            values = ", ".join(f"{n}={v:g}" for n, v in zip(
                self._y_names + self._r_names, [*y_phys, *r_phys], strict=True))
            raise CosimError(f"controller {self.name!r}: non-finite input at t={t:g} s "
                             f"({values})")
        y = self.model.normalize_y(y_phys)
        y_ref = self.model.normalize_y(r_phys)
        held = self.held
        if held.shift is not None:
            held.measure(self._values, t, self.fhocp, self.law)
        if self.observer.x_hat is None:
            self.observer.init_from_output(y)
        e_o = self.observer.e_o
        x_start = held.ahead(self.observer, self.fhocp)
        step = (self.law.step(self.observer, y, y_ref, t) if x_start is None
                else self.law.step(self.observer, y, y_ref, t, x_start=x_start))
        rec, res = step.record, step.record.result
        if held.shift is not None and rec.fallback and not rec.candidate_feasible:
            # a measured disturbance moved the steady states beyond the plan: start again
            # from the equilibrium of the output estimate at the disturbance now measured
            self.law.restart()
        self.observer.make_step(held.model_input(rec.u, self.fhocp), y)
        held.applied(rec.u)
        self._u_phys = np.clip(self.model.denormalize_u(rec.u), self._lo, self._hi)
        self._diag = {
            "solve_ms": res.solve_time * 1e3,
            "iterations": float(res.iterations),
            "status": float(status_code(res.status)),
            "cost": float(res.cost) if math.isfinite(res.cost) else float("nan"),
            "alpha": self.law.alpha,
            "e_o": e_o,
            "x_hat_error_bound": e_o,
            "active_constraints": float(res.active),
            "fallback": float(rec.fallback),
            "suboptimal": float(rec.suboptimal),
            "setpoint_rejected": float(step.rejected),
            "governor_lambda": step.governor_lambda,
            **step.diagnostics,
        }

    def diagnostics(self) -> dict[str, float]:
        return dict(self._diag)

    def summary(self) -> dict:
        from controllers.ocp.paper_mpc import solver_summary

        out = solver_summary(self.law.records)
        out.update(self.certification.summary())
        out.update({
            "controller": "robust-mpc",
            "law": self.law.name,
            "model": str(self.model_path),
            "problem": self.problem.name,
            "N": self.fhocp.N,
            "formulation": self.fhocp.formulation,
            "kernel": "compiled" if self.fhocp.kernel is not None else "numpy",
            "du_weight": {n: float(w) for n, w in zip(self._u_names, self.du_weight,
                                                      strict=True)},
            "gain_scale": self.cert.gain_scale,
            **self.held.summary(),
            **self.law.summary(),
            "options": _plain(self.options.to_dict()),
        })
        return out

    def terminate(self) -> None:
        """Nothing to release (the casadi solver is freed with the object)."""
