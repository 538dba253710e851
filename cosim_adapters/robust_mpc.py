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
  tracking FHOCP of :mod:`controllers.fhocp_tracking` (an artificial steady state as a
  decision variable, offset-free through the disturbance estimate ``d̂`` in the cost, the
  input-rate terms of ``du_weight``); every set-point is accepted, and an unreachable or
  inadmissible one is tracked to the closest admissible steady state (docs:
  design/tracking.md).
- ``"paper"``: the paper's law, with its set-point handling in :mod:`cosim_adapters.paper_law`:
  when ``ȳ`` changes, the equilibrium ``(x̄, ū)`` and ``α`` (``eq:def-alpha``) via
  :meth:`controllers.certificates.Certificate.reference`, which also checks Assumption 1
  (``ass:setpoint``) and ``eq:condition-recursive-feasibility``; then ``u_k =
  k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``, :class:`controllers.robust_mpc.RobustMPC`: the FHOCP
  ``eq:optimization`` with the shifted-candidate fallback).

Any numbers of inputs ``m`` and outputs ``p`` (the problem's). With more outputs than inputs
(``p > m``) only set-points on the model's ``m``-dimensional surface of equilibrium outputs
are reachable: the tracking law steers to the closest one, the paper's law refuses the
others like any unreachable set-point, naming the closest reachable equilibrium output.

The paper's law and set-points outside its theory (unreachable, or failing Assumption 1 /
eq. 11): the controller keeps regulating to the last admissible set-point, counts the step in
``setpoint_rejected`` (diagnostics and summary) and names the failed hypothesis (or, for an
unreachable one, the closest reachable equilibrium output) in the summary. A first set-point
that is already inadmissible is a configuration error (:class:`cosim.errors.CosimError`, the
same reason). Its set-point changes go through the admissible reference governor of
:mod:`controllers.governor` (on by default, ``governor=False`` gives the paper's controller,
which switches ``(x̄, ū, α)`` at once): the set-point handed to the FHOCP moves towards the
requested one only as far as a sequence known to be feasible exists, by at most a fraction
``λ_max`` of the way that halves after a solve that did not converge and doubles after one
that did; that sequence is the solver's initial guess and the fallback. Under the paper's
law ``du_weight`` (off by default) adds the input-rate penalty ``Σ_i (u_i − u_{i−1})ᵀ S (u_i
− u_{i−1})`` (normalised units, ``u_{−1}`` the input applied at the previous step;
:mod:`controllers.input_rate`), outside the paper's cost, and ``offset_free=True`` (outside
the theorem) shifts the model set-point by a filtered estimate ``d̂`` of the output mismatch
``y − ŷ`` (``ȳ_model = ȳ − d̂``); the shifted set-point must still pass the checks.

This module is the co-simulation adapter (a :class:`cosim.component.Component`) of the
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
from controllers.solve_status import status_code
from cosim.component import Component, Signal
from cosim.errors import CosimError
from cosim_adapters.certification import (
    CERTIFICATE_MODES,
    Certification,
    check_setpoints,
    go_uncertified,
)
from cosim_adapters.law import ControlLaw
from cosim_adapters.paper_law import PaperLaw
from cosim_adapters.tracking import TrackingLaw, check_law

__all__ = ["RobustMPCController"]


def _check_options(*, name: Any, offset_free: Any, offset_filter: Any, setpoint_rate: Any,
                   governor: Any, solver: Any, ipopt_options: Any, max_iter: Any,
                   kernel: Any, du_weight: Any) -> None:
    """Reject controller options of the wrong type or range with a one-line error."""

    def number(value: Any) -> bool:
        return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(
            value)

    if not isinstance(name, str) or not name:
        raise CosimError(f"option name={name!r}: expected a non-empty string")
    for key, value in (("offset_free", offset_free), ("governor", governor)):
        if not isinstance(value, bool):
            raise CosimError(f"option {key}={value!r}: expected true or false")
    if not number(offset_filter) or not 0 < offset_filter <= 1:
        raise CosimError(f"option offset_filter={offset_filter!r}: expected a number in (0, 1]")
    if setpoint_rate is not None and (not number(setpoint_rate) or setpoint_rate <= 0):
        raise CosimError(f"option setpoint_rate={setpoint_rate!r}: expected a positive number "
                         "of output units per sample")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or not 1 <= max_iter <= 10000:
        raise CosimError(f"option max_iter={max_iter!r}: expected an integer in [1, 10000]")
    if kernel not in ("auto", "numpy"):
        raise CosimError(f"option kernel={kernel!r}: expected \"auto\" or \"numpy\"")
    if solver is not None and solver not in ("sqp", "ipopt"):
        raise CosimError(f"option solver={solver!r}: expected \"sqp\" or \"ipopt\"")
    if ipopt_options is not None and (not isinstance(ipopt_options, Mapping) or not all(
            isinstance(k, str) for k in ipopt_options)):
        raise CosimError(f"option ipopt_options={ipopt_options!r}: expected an object of "
                         "IPOPT option names and values")
    weights = list(du_weight.values()) if isinstance(du_weight, Mapping) else [du_weight]
    if not all(number(w) and w >= 0 for w in weights):
        raise CosimError(f"option du_weight={du_weight!r}: expected a non-negative number or "
                         "an object of non-negative numbers by input name (normalised units)")


def _weight(key: str, value: Any, size: int, names: list[str] | None) -> np.ndarray | None:
    """A cost weight option as a matrix: ``None`` (the default), a number (times the
    identity), an object by signal name (diagonal; ``names`` given) or a matrix."""
    if value is None:
        return None
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
    if w.shape != (size, size) or not np.all(np.isfinite(w)):
        raise CosimError(f"option {key}: expected a number or a {size}x{size} matrix, got "
                         f"shape {w.shape}")
    return w


class RobustMPCController(Component):
    """Robust MPC with GRU model and observer (Schimperna & Magni), normalised internally.

    Parameters
    ----------
    model : str or Path, optional
        Model file (default: the shipped ``controllers/models/fourtank_gru.json``).
    problem : str or Path, optional
        A problem file: must be the model's own (a check), or the problem of a model file
        that has none (:mod:`cosim_adapters.problems`).
    N : int, optional
        Prediction horizon (default 80, :data:`controllers.fhocp_tracking.DEFAULTS`; the
        paper's 15 with ``law="paper"``).
    Q, R : array, number or mapping, optional
        Cost weights in normalised units (default ``I_n`` and ``0.01 I_m``, paper section V):
        a matrix, one number (times the identity) or, for ``R``, an object of diagonal
        weights by input name (inputs not named: 0.01).
    e_o0 : float
        ``ê_o,0`` (paper: 0.02).
    gain_scale : float, optional
        Observer gains = ``gain_scale`` × the LP gains; default: the gains in the model file
        (``cosim certify --save``), else the largest scale passing every hypothesis at
        :func:`controllers.gain_design.default_setpoints` (a grid over the output box)
        (:func:`controllers.gain_design.choose_gain_scale`).
    offset_free : bool
        ``law="paper"``: offset-free set-point correction (outside the theorem, see the
        module docstring).
    offset_filter : float, optional
        Filter constant ``β`` of ``d̂ ← d̂ + β (y − ŷ − d̂)`` (default 0.3; 0.05 with
        ``law="paper"``).
    governor : bool, optional
        ``law="paper"``: admissible reference governor after set-point changes (default
        on; see the module docstring and :mod:`controllers.governor`). ``False``: the
        paper's FHOCP with the new ``(x̄, ū, α)`` at once.
    setpoint_rate : float, optional
        ``law="paper"``, outside the theorem: move the set-point given to the FHOCP towards
        the requested one by at most this much per sample, in the outputs' units (a
        rate-limiting reference governor), so that the terminal set stays reachable after
        large steps. Off by default.
    solver : {"sqp", "ipopt"}, optional
        NLP solver of the FHOCP (default: SQP with a dense QP, or IPOPT when
        ``ipopt_options`` are given; see :class:`controllers.fhocp.FHOCP`).
    ipopt_options : dict, optional
        Overrides of :data:`controllers.solver_settings.FAST_IPOPT_OPTIONS`.
    kernel : {"auto", "numpy"}
        Where the SQP's derivatives come from: the compiled kernel (``"auto"``, built on
        first use; the numpy callbacks when no C compiler is found) or the numpy callbacks
        (``"numpy"``, the reference implementation). Same answers either way.
    du_weight : float or mapping, optional
        Weight ``S`` of the input-rate penalty ``Σ_i (u_i − u_{i−1})ᵀ S (u_i − u_{i−1})`` in
        normalised units (``u`` ∈ [−1, 1]; ``u_{−1}`` the input applied at the previous
        step), one number for every input or an object by the problem's input names
        (``{"qa": 5, "qb": 5}``; inputs not named: 0). Default 0.05 (the tracking law,
        which adds the terminal term ``‖u_{N−1} − u_s‖²_S``); 0 with ``law="paper"``: the
        paper's cost, which the term leaves.
    law : {"tracking", "paper"}
        ``"tracking"`` (default): the tracking FHOCP (:mod:`cosim_adapters.tracking`,
        :mod:`controllers.fhocp_tracking`): an artificial steady state as a decision
        variable, offset-free through ``d̂`` in the cost, no governor, nothing rejected (an
        unreachable or inadmissible set-point is tracked to the closest admissible steady
        state); zero observer gains. ``"paper"``: the paper's FHOCP with the set-point's
        equilibrium, the governor and set-point rejection.
    offset_weight : float or mapping
        ``law="tracking"``: diagonal of the offset weight ``T`` of ``‖g(x_s) + d̂ − ȳ‖²_T``
        (normalised outputs; one number or an object by output name, outputs not named:
        10⁴). Default 10⁴.
    alpha_c : float, optional
        ``law="tracking"``: the terminal set's radius (normalised state, ∞-norm); default the
        certified design's ``α_min(N)``, which makes ``Y_s`` its admissible box.
    control_horizon : int, optional
        ``law="tracking"``: the number ``M ≤ N`` of free inputs ``u_0 … u_{M−1}``; the
        others are held at the artificial steady input ``u_s`` (the guarantees unchanged:
        :class:`controllers.fhocp_tracking.TrackingFHOCP`). Default ``⌈N / 4⌉`` (20 at the
        default N = 80).
    certificate : {"auto", "require", "keep"}
        Where the certificate does not cover the run (a hypothesis fails, or a set-point of
        the run lies outside the certified set): ``"auto"`` runs uncertified, with the
        model's measured prediction error as the tightening; ``"require"`` refuses
        (:class:`cosim.errors.CosimError`, exit 2); ``"keep"`` keeps the certified design
        (the tracking law tracks such a set-point to the closest admissible steady output,
        the paper's law refuses it; a design whose hypotheses fail is an error), as before
        graded guarantees (:mod:`cosim_adapters.certification`).
    max_iter : int, optional
        Iteration cap of one FHOCP solve, the real-time bound (default 40; 15 with
        ``law="paper"``). A solve that reaches it applies its feasible iterate
        (suboptimal MPC) or the fallback; that iterate depends on the last bits of the
        arithmetic, so the regression references are recorded with a cap every solve
        converges within (``max_iter=200``).
    name : str
        Component name.
    """

    direct_feedthrough = True
    #: wall-clock diagnostics: written by the master to timings.csv, not results.csv
    timing_diagnostics = frozenset({"solve_ms"})

    def __init__(self, model: str | Path | None = None, problem: str | Path | None = None,
                 N: int | None = None,
                 Q: Any = None, R: Any = None,
                 e_o0: float = 0.02, gain_scale: float | None = None,
                 offset_free: bool = False, offset_filter: float | None = None,
                 setpoint_rate: float | None = None, governor: bool | None = None,
                 solver: str | None = None,
                 ipopt_options: Mapping[str, Any] | None = None, max_iter: int | None = None,
                 kernel: str = "auto", du_weight: float | Mapping[str, float] | None = None,
                 law: str = "tracking", offset_weight: float | Mapping[str, float] | None = None,
                 alpha_c: float | None = None, control_horizon: int | None = None,
                 certificate: str = "auto", name: str = "mpc") -> None:
        from controllers import certificates as certs
        from controllers import gain_design
        from controllers.model import GRUModel
        from controllers.observer import GRUObserver

        tracking = check_law(law, governor=governor, offset_free=offset_free,
                              setpoint_rate=setpoint_rate, offset_weight=offset_weight,
                              alpha_c=alpha_c, control_horizon=control_horizon)
        from controllers.fhocp_tracking import DEFAULTS as TRACKING

        N = (TRACKING["N"] if tracking else 15) if N is None else N
        if max_iter is None:
            max_iter = TRACKING["max_iter"] if tracking else 15
        governor = (not tracking) if governor is None else governor
        if offset_filter is None:
            offset_filter = TRACKING["offset_filter"] if tracking else 0.05
        if du_weight is None:
            du_weight = TRACKING["du_weight"] if tracking else 0.0
        _check_options(name=name, offset_free=offset_free, offset_filter=offset_filter,
                       setpoint_rate=setpoint_rate, governor=governor, solver=solver,
                       ipopt_options=ipopt_options, max_iter=max_iter, kernel=kernel,
                       du_weight=du_weight)
        self.name = name
        self.model_path = Path(model) if model is not None else DEFAULT_MODEL
        try:
            self.model = GRUModel.load(self.model_path)
        except ControllersError as exc:
            raise CosimError(str(exc)) from None
        from cosim_adapters.problems import problem_for

        self.problem = problem_for(self.model, problem)
        self.model.problem = self.problem
        from controllers.input_rate import du_weights

        try:
            self.du_weight = du_weights(du_weight, len(self.problem.input_names),
                                        list(self.problem.input_names))
        except ControllersError as exc:
            raise CosimError(f"option {exc}") from None
        kwargs: dict[str, Any] = {"N": N, "Q": _weight("Q", Q, self.model.n, None),
                                  "R": _weight("R", R, len(self.problem.input_names),
                                               list(self.problem.input_names)),
                                  "e_o0": e_o0}
        if certificate not in CERTIFICATE_MODES:
            raise CosimError(f"option certificate={certificate!r}: expected one of "
                             f"{', '.join(map(repr, CERTIFICATE_MODES))}")
        self.certificate_mode = certificate
        gains_certified = True
        try:
            if gain_scale is None and self.model.L_z is None:
                targets = [self.model.normalize_y(np.array(y))
                           for y in gain_design.default_setpoints(self.problem)]
                theta, cert = gain_design.choose_gain_scale(self.model, targets, **kwargs)
                if theta is None:
                    gains_certified = False
                    cert = certs.compute_certificate(self.model, gain_scale=0.0, **kwargs)
            else:
                cert = certs.compute_certificate(self.model, gain_scale=gain_scale, **kwargs)
        except ControllersError as exc:  # a bad design or a model without certificate
            raise CosimError(str(exc)) from None
        fhocp_options: dict[str, Any] = dict(
            solver=solver, sqp_options={"max_iter": max_iter}, kernel=kernel,
            du_weight=self.du_weight,
            ipopt_options={"max_iter": max_iter, **(ipopt_options or {})}
            if ipopt_options or solver == "ipopt" else None)
        #: the control law (:class:`cosim_adapters.law.ControlLaw`): everything that differs
        #: between ``law="tracking"`` and ``law="paper"``
        self.law: ControlLaw
        if tracking:
            design = {"kwargs": kwargs, "fhocp_options": fhocp_options,
                      "offset_weight": offset_weight, "alpha_c": alpha_c,
                      "offset_filter": offset_filter, "control_horizon": control_horizon}
            self.law, failed = TrackingLaw.build(self.model, cert, design, name,
                                                 gains_certified)
        else:
            failed = cert.failures()
            self.law = PaperLaw(self.model, cert, fhocp_options, governor=governor,
                                offset_free=offset_free, offset_filter=offset_filter,
                                setpoint_rate=setpoint_rate, name=name)
        self.fhocp, self.cert = self.law.fhocp, self.law.cert
        # load scipy.optimize (the observer's x̂_0 equilibrium) now, so that the first
        # control step is a normal one (importing scipy.optimize: ~0.2 s)
        import scipy.optimize  # noqa: F401

        self.observer = GRUObserver.from_certificate(self.cert)
        pr = self.problem
        self._y_names = list(pr.output_names)
        self._r_names = [f"ref.{n}" for n in self._y_names]
        self._u_names = list(pr.input_names)
        self.inputs = tuple(Signal(c.name, c.unit, c.description or f"measured {c.name}")
                            for c in pr.outputs) + tuple(
            Signal(f"ref.{c.name}", c.unit, f"set-point of {c.name}") for c in pr.outputs)
        self.outputs = tuple(Signal(c.name, c.unit, c.description) for c in pr.inputs)
        self.sample_time = float(self.model.Ts)
        self.bounds = pr.bounds()
        self._lo = np.array([c.min for c in pr.inputs])
        self._hi = np.array([c.max for c in pr.inputs])
        self._values: dict[str, float] = {}
        #: The observer's initial state ``x̂_0`` (normalised), or ``None``: the equilibrium for
        #: the first measured output (paper section V). Read by :meth:`setup`.
        self.initial_estimate: np.ndarray | None = None
        #: certified, or uncertified with the reason (:mod:`cosim_adapters.certification`)
        self.certification = Certification()
        self._expected: list[dict[str, float]] | None = None
        if failed:
            go_uncertified(self, "; ".join(failed))
        self.setup(0.0)

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
        self.fhocp.setup()
        self.observer.kernel = self.fhocp.kernel   # its compiled GRU step (same model)
        self.law.reset()
        self._u_phys = 0.5 * (self._lo + self._hi)
        self._diag: dict[str, float] = {}

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
        if self.observer.x_hat is None:
            self.observer.init_from_output(y)
        e_o = self.observer.e_o
        step = self.law.step(self.observer, y, y_ref, t)
        rec, res = step.record, step.record.result
        self.observer.make_step(rec.u, y)
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
        from controllers.robust_mpc import solver_summary

        out = solver_summary(self.law.records)
        law = self.law.summary()
        out.update({k: law.pop(k) for k in ("alpha_c", "control_horizon", "offset_weight",
                                            "offset_filter", "tracking_hypotheses")
                    if k in law})
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
            **law,
        })
        return out

    def terminate(self) -> None:
        """Nothing to release (the casadi solver is freed with the object)."""
