"""The robust GRU MPC of the paper (Fig. 1: observer + FHOCP) as a co-simulation component.

:class:`RobustMPCController` binds the controller of the numerical core,
:class:`controllers.mpc.RobustMPC` (its observer, held inputs and law; what each law does:
:mod:`controllers.laws`), to the co-simulation: it reads the measured outputs of its control
problem (the model file's, :class:`controllers.problem.ControlProblem`), their set-points
``ref.<output>`` and the measured disturbances ``dist.<name>``, and writes its inputs, all
in the problem's units (for the four-tank: levels ``h1``, ``h2`` in metres, pump flows
``qa``, ``qb`` in m³/s). It declares what it offers (:class:`cosim.core.component.
Capability`): it designs for the run's set-points (certified or not), measures disturbances
with nominal defaults, is told those known ahead, says why it runs uncertified, takes its
settings between steps by name (:meth:`RobustMPCController.set`): the engineer's weights and
the operator's ``op.*`` settings (:mod:`controllers.operator`: its outputs are then the
inputs the plant gets, its diagnostics ``computed.<input>`` what the law computed), and says
what it plans (:meth:`RobustMPCController.prediction`).

Its errors are the numerical core's, in the same words, as :class:`cosim.core.errors.
CosimError`: a design or a first set-point outside the theory is a configuration error
(exit 2).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controllers.errors import ControllersError
from controllers.model import DEFAULT_MODEL
from controllers.mpc_options import MPCOptions
from cosim.core.component import Capability, Component, Prediction, Setting, Signal
from cosim.core.errors import CosimError

__all__ = ["RobustMPCController"]


class RobustMPCController(Component):
    """Robust MPC with GRU model and observer (Schimperna & Magni), normalised internally.

    Parameters
    ----------
    model : str or Path, optional
        Model file (default: the shipped ``controllers/models/fourtank_gru.json``).
    problem : str or Path, optional
        A problem file: must be the model's own (a check; its ``[mpc]`` table, the tuning,
        may differ and, when it has one, is the one used), or the problem of a model file
        that has none (:mod:`cosim.adapters.problems`).
    options : MPCOptions or mapping, optional
        The design (:class:`controllers.mpc_options.MPCOptions`), as an object (used as
        it is) or by key (over the problem's ``[mpc]`` table,
        :meth:`~controllers.mpc_options.MPCOptions.resolve`).
    name : str
        Component name.
    **option_values
        Options by name (the attributes of :class:`~controllers.mpc_options.MPCOptions`,
        which say what each one does, and the law's own: :mod:`controllers.laws`), over
        ``options``.

    Attributes
    ----------
    mpc : RobustMPC
        The controller (:class:`controllers.mpc.RobustMPC`).
    """

    direct_feedthrough = True
    capabilities = frozenset({Capability.SETPOINTS, Capability.DISTURBANCES,
                              Capability.PREVIEW, Capability.NOTICE, Capability.SETTINGS,
                              Capability.ESTIMATE, Capability.OPERATOR,
                              Capability.PREDICTION})
    #: the options :func:`cosim.core.registry.create` accepts (``--option KEY=VALUE``)
    OPTIONS = ("model", "problem", "options", "name", *MPCOptions.names())
    #: wall-clock diagnostics: written by the master to timings.csv, not results.csv
    timing_diagnostics = frozenset({"solve_ms"})

    def __init__(self, model: str | Path | None = None, problem: str | Path | None = None,
                 options: MPCOptions | Mapping[str, Any] | None = None, *,
                 name: str = "mpc", **option_values: Any) -> None:
        from controllers.model import GRUModel
        from controllers.mpc import RobustMPC
        from cosim.adapters.problems import problem_for

        if not isinstance(name, str) or not name:
            raise CosimError(f"option name={name!r}: expected a non-empty string")
        self.name = name
        self.model_path = Path(model) if model is not None else DEFAULT_MODEL
        try:
            gru = GRUModel.load(self.model_path)
            gru.problem = problem_for(gru, problem)
            if not isinstance(options, MPCOptions):
                options = MPCOptions.resolve({**(options or {}), **option_values},
                                             gru.problem)
            elif option_values:
                options = MPCOptions.from_mapping({**options.to_dict(), **option_values})
            self.mpc = RobustMPC(gru, options, name)
        except ControllersError as exc:
            raise _as_cosim(exc) from None
        self.problem = gru.problem
        self._signals()

    def _signals(self) -> None:
        """The component's signals, sample time and boxes, from the control problem."""
        pr = self.problem
        self._y_names = list(pr.output_names)
        self._r_names = [f"ref.{n}" for n in self._y_names]
        self._d_names = [f"dist.{c.name}" for c in pr.disturbances]
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
        self.previewed = self.mpc.previewed
        self.outputs = tuple(Signal(c.name, c.unit, c.description) for c in pr.inputs)
        self.sample_time = float(self.mpc.model.Ts)
        self.bounds = pr.bounds()
        self._values: dict[str, float] = {}
        self._u_phys = 0.5 * (self.mpc.u_lo + self.mpc.u_hi)
        self._diag: dict[str, float] = {}

    @property
    def notice(self) -> str | None:  # type: ignore[override]
        """The one line to show before a run (why it runs uncertified), else ``None``."""
        return self.mpc.notice

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:
        """Check the run's set-points against the certified design
        (:meth:`controllers.mpc.RobustMPC.expect_setpoints`)."""
        try:
            self.mpc.expect_setpoints(setpoints)
        except ControllersError as exc:
            raise _as_cosim(exc) from None

    # -- Component interface -----------------------------------------------------------
    def setup(self, t0: float) -> None:
        """Reset the controller and every counter for a run starting at ``t0``."""
        self.mpc.reset()
        self._u_phys = 0.5 * (self.mpc.u_lo + self.mpc.u_hi)
        self._diag = {}

    def set_schedule(self, schedule: Mapping[str, Any] | None) -> None:
        """The values to come of the disturbances known ahead, for this run (after
        :meth:`setup`): :meth:`controllers.mpc.RobustMPC.set_schedule`."""
        self.mpc.set_schedule(schedule)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._values.update({k: float(v) for k, v in values.items()})

    def get_outputs(self) -> dict[str, float]:
        return {n: float(u) for n, u in zip(self._u_names, self._u_phys, strict=True)}

    def step(self, t: float, dt: float) -> None:
        """Compute ``u_k`` from the measured outputs, the set-points and the measured
        disturbances at ``t``; advance the observer."""
        values = self._values
        try:
            y = np.array([values[n] for n in self._y_names])
            r = np.array([values[n] for n in self._r_names])
        except KeyError as exc:
            raise CosimError(f"controller {self.name!r}: input {exc.args[0]!r} was never set "
                             f"(wire {', '.join(self._y_names + self._r_names)})") from None
        d = None
        if self._d_names:
            try:
                d = np.array([values[n] for n in self._d_names])
            except KeyError as exc:
                raise CosimError(f"controller {self.name!r}: input {exc.args[0]!r} was never "
                                 f"set (wire {', '.join(self._d_names)})") from None
        try:
            step = self.mpc.step(y, r, d, t)
        except ControllersError as exc:
            raise _as_cosim(exc) from None
        self._u_phys, self._diag = step.u, dict(step.diagnostics)
        self._diag.update({f"computed.{n}": float(v)
                           for n, v in zip(self._u_names, step.computed, strict=True)})

    def diagnostics(self) -> dict[str, float]:
        return dict(self._diag)

    def settings(self) -> dict[str, Setting]:
        """What :meth:`set` takes: the law's (:meth:`controllers.mpc.RobustMPC.settings`)
        and the operator's (:meth:`controllers.mpc.RobustMPC.operator_settings`, role
        ``"operator"``)."""
        units = self.problem.units()
        out = {name: Setting(name, low, high, text, value)
               for name, low, high, text, value in self.mpc.settings()}
        for name, low, high, text, value in self.mpc.operator_settings():
            signal = name.split(".")[2] if name.count(".") == 2 else ""
            unit = units.get(signal, "") if name.startswith(("op.min", "op.max",
                                                              "op.manual")) else ""
            out[name] = Setting(name, low, high, text, value, unit, role="operator")
        return out

    def set(self, name: str, value: float) -> str:
        """Setting ``name`` from the next step on: an operator's (``op.*``,
        :meth:`controllers.mpc.RobustMPC.operate`) or the law's
        (:meth:`controllers.mpc.RobustMPC.set`); what was re-derived."""
        try:
            if name.startswith("op."):
                return self.mpc.operate(name, value)
            return self.mpc.set(name, value)
        except ControllersError as exc:
            raise _as_cosim(exc) from None

    def operator_status(self) -> dict[str, Any]:
        """The outputs the last plan predicts over the horizon and the RMS of the k-step
        errors so far (:class:`controllers.shadow.PredictionWatch`), by output."""
        watch = self.mpc.operating.watch
        errors = watch.summary()["outputs"]
        return {"prediction": watch.last_prediction(),
                "prediction_error": {y: e["rms"] for y, e in errors.items()}}

    def set_initial_estimate(self, x0: Sequence[float] | None) -> float:
        """The observer's start (:attr:`controllers.mpc.RobustMPC.initial_estimate`; a
        campaign's drawn ``x̂_0``) and its bound ``ê_o,0``."""
        self.mpc.initial_estimate = None if x0 is None else np.asarray(x0, dtype=float)
        return float(self.mpc.cert.e_o0)

    def estimate(self) -> tuple[Any, float, Any]:
        """The observer's ``x̂`` and ``ê_o``, and the law's steady state."""
        obs = self.mpc.observer
        return obs.x_hat, obs.e_o, self.mpc.law.steady_state

    def prediction(self) -> Prediction | None:
        """The last step's plan in the problem's units: the law's last solve (its states
        ``x_0 … x_N`` through the output map, plus the offset-free estimate ``d̂`` the law
        aims off by, so that they compare with the measurements), its inputs, and the
        tightened output rows ``eq:optimization-constraint`` at ``ê_o`` of that step, read
        as each output's box; ``None`` before the first step."""
        mpc = self.mpc
        records = mpc.law.records
        if not records:
            return None
        rec = records[-1]
        res, fh, model = rec.result, mpc.fhocp, mpc.model
        scale = np.asarray(model.y_scale, dtype=float)
        d = np.array([self._diag.get(f"d_hat_{n}", 0.0) for n in self._y_names],
                     dtype=float) / np.abs(scale)
        y = model.denormalize_y(res.x @ fh.params["U_o"].T + fh.params["b_o"] + d)
        u = np.clip(model.denormalize_u(res.u), self.mpc.u_lo, self.mpc.u_hi)
        low, high = _output_rows(fh, fh.tightened_bounds(rec.e_o), d)
        low, high = model.denormalize_y(low), model.denormalize_y(high)
        flip = scale < 0   # a negative scale swaps the ends
        low[:, flip], high[:, flip] = high[:, flip], low[:, flip].copy()
        names = self._y_names
        return Prediction(
            step=float(model.Ts),
            outputs={n: tuple(map(float, y[:, j])) for j, n in enumerate(names)},
            inputs={n: tuple(map(float, u[:, j])) for j, n in enumerate(self._u_names)},
            low={n: tuple(map(float, low[:, j])) for j, n in enumerate(names)},
            high={n: tuple(map(float, high[:, j])) for j, n in enumerate(names)},
            fallback=bool(rec.fallback))

    def summary(self) -> dict:
        out = self.mpc.summary()
        law = out.pop("law")
        return {**out, "controller": "robust-mpc", "law": law, "model": str(self.model_path)}

    def terminate(self) -> None:
        """Nothing to release (the solver is freed with the object)."""


def _output_rows(fh: Any, bounds: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows ``L U_o x_i ≤ bounds_i`` of ``eq:optimization-constraint`` (``i = 0 … N−1``)
    read as the box each output keeps, normalised: the row ``+y_j`` an upper end, ``−y_j`` a
    lower one (``nan`` where the problem has no such row), plus ``b_o`` and the offset ``d``
    the prediction carries. The four-tank's ``L`` holds both rows of every output
    (:func:`controllers.problem.output_constraints`)."""
    L = np.asarray(fh.L, dtype=float)
    N, p = bounds.shape[0], L.shape[1]
    low, high = np.full((N, p), np.nan), np.full((N, p), np.nan)
    offset = np.asarray(fh.params["b_o"], dtype=float) + d
    for r, row in enumerate(L):
        j = int(np.argmax(np.abs(row)))
        if np.count_nonzero(row) != 1 or abs(abs(row[j]) - 1.0) > 1e-12:
            continue
        if row[j] > 0:
            high[:, j] = bounds[:, r] + offset[j]
        else:
            low[:, j] = -bounds[:, r] + offset[j]
    return low, high


def _as_cosim(exc: ControllersError) -> CosimError:
    """The numerical core's error as the co-simulation's, in the same words (a
    :class:`~controllers.certification.grade.NotUsable` keeps its ``why``)."""
    from controllers.certification.grade import NotUsable

    error = CosimError(str(exc))
    if isinstance(exc, NotUsable):
        error.why = exc.why  # type: ignore[attr-defined]
    return error
