"""Decentralised PI baseline: the controller the MPC is compared to, on any square plant.

One independent discrete PI loop per output, sampled at ``Ts``, each with input saturation to
the problem's box and back-calculation anti-windup (Åström & Hägglund)::

    e_k   = r_k − y_k
    v_k   = I_k + K e_k                       (unsaturated)
    u_k   = sat(v_k)                          (held over [t_k, t_k + Ts))
    I_k+1 = I_k + K Ts / Ti · e_k + Ts / Tt · (u_k − v_k)

Which input controls which output, and the gains, come from (first that applies):

1. ``loops``: given explicitly;
2. ``pairing``: one of the control problem's named ``[pi]`` pairings
   (:class:`controllers.problem.ControlProblem`);
3. the problem's default ``[pi]`` pairing, when it has one (the four-tank's problem file
   explains its pairing: the negative relative gain of the diagonal one);
4. tuned from the identified GRU model (``model``, or ``cosim run --model``) when the
   problem has no ``[pi]`` table, or when ``tune=True``: pairing by the relative gain array,
   SIMC rules on first-order-plus-dead-time fits of the model's step responses
   (:mod:`controllers.pi_tuning`); ``summary.json`` records the operating point, the gain
   matrix, the RGA and each loop's fit and gains.

Without any of these the controller refuses to start, as it does on a plant with more
inputs than outputs or the reverse (use the robust MPC there).

With measured disturbances (the problem's ``[disturbances]``) and a model, the PI adds a
static feedforward (option ``feedforward``, on by default then): ``u = PI(e) + K_ff (d −
d_0)``, ``K_ff = −G_u⁺ G_d`` from the model's steady-state gains at the operating point
(:func:`controllers.disturbances.feedforward_gain`), ``d_0`` the disturbances' nominal values
(the middle of their boxes); ``feedforward=False`` gives the plain PI, which sees a
disturbance only once it has moved the outputs. The loops are tuned on the model with the
disturbances held at ``d_0``.

An operator runs it as the robust MPC (:mod:`controllers.operator`, ``op.*`` settings): in
manual, for an input out of service or an output not controlled (its loop opened) the
plant gets the operator's or the held input and the loop's integrator is back-calculated to
it (``I = u − K e − K_ff (d − d_0)``: the transfer back is bumpless); an input limit narrows
its saturation (anti-windup as above); ``max_move`` limits each move. Its outputs are
unconstrained: operator limits on them are refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from controllers import pi_tuning
from controllers.disturbances import condition, feedforward_gain
from controllers.model import GRUModel
from controllers.pi_tuning import PITuning
from controllers.problem import ControlProblem, PILoop
from cosim.core.component import Capability, Component, Setting, Signal
from cosim.core.errors import CosimError

__all__ = ["PIController", "PILoop"]


def _loops(problem: ControlProblem, pairing: str | None,
           loops: Sequence[Any] | None) -> tuple[PILoop, ...]:
    """The loops: given, or the problem's pairing ``pairing`` (default its own)."""
    if loops is not None:
        if pairing is not None:
            raise CosimError("controller 'pi': give loops or pairing, not both")
        return _given_loops(problem, loops)
    if not problem.pairings:
        raise CosimError(f"controller 'pi': the problem {problem.name!r} "
                         f"({problem.source or 'no file'}) has no [pi] loops: add them to "
                         "the problem file, give --option loops=[...], or give a model "
                         "(--model FILE) to tune them from")
    name = problem.pairing if pairing is None else pairing
    if name not in problem.pairings:
        raise CosimError(f"controller 'pi': unknown pairing {name!r} (the problem's: "
                         f"{', '.join(problem.pairings)})")
    return tuple(problem.pairings[name])


def _tuned(gru: Any, problem: ControlProblem, setpoint: Any, tau_c: Any) -> PITuning:
    """Loops tuned from the model ``gru`` (:func:`controllers.pi_tuning.tune`)."""
    from controllers.errors import ControllersError, UnreachableSetpoint

    if tau_c is not None and (isinstance(tau_c, bool) or not isinstance(tau_c, int | float)
                              or not math.isfinite(tau_c) or tau_c <= 0):
        raise CosimError(f"controller 'pi': tune_tau_c must be a positive number of seconds, "
                         f"got {tau_c!r}")
    target = None
    if setpoint is not None:
        given = _by_name("tune_setpoint", setpoint, problem.output_names, "output")
        target = [given.get(c.name, 0.5 * (c.min + c.max)) for c in problem.outputs]
    if gru.problem is None:  # a model file without a problem: the one it was checked against
        gru = replace(gru, problem=problem)
    gru = condition(gru)
    try:
        return pi_tuning.tune(gru, setpoint=target, tau_c=tau_c)
    except UnreachableSetpoint as exc:
        raise CosimError(f"controller 'pi': tune_setpoint: {exc}") from None
    except ControllersError as exc:
        raise CosimError(f"controller 'pi': cannot tune the loops from "
                         f"{gru.source or 'the model'}: {exc}") from None


def _given_loops(problem: ControlProblem, loops: Sequence[Any]) -> tuple[PILoop, ...]:
    out = []
    for lp in loops:
        if isinstance(lp, PILoop):
            out.append(lp)
            continue
        keys = {"output", "input", "K", "Ti", "Tt"}
        if not isinstance(lp, Mapping) or not {"output", "input", "K", "Ti"} <= set(lp) \
                or set(lp) - keys:
            raise CosimError(f"controller 'pi': loops: each loop is {{output, input, K, Ti, "
                             f"Tt}}, got {lp!r}")
        vals = [lp["K"], lp["Ti"], lp.get("Tt", lp["Ti"])]
        if not all(isinstance(v, int | float) and not isinstance(v, bool)
                   and math.isfinite(v) for v in vals) or vals[0] == 0 or min(vals[1:]) <= 0:
            raise CosimError(f"controller 'pi': loops: {lp!r} needs K != 0, Ti > 0, Tt > 0")
        out.append(PILoop(str(lp["output"]), str(lp["input"]), *(float(v) for v in vals)))
    ys, us = [lp.y for lp in out], [lp.u for lp in out]
    if sorted(ys) != sorted(problem.output_names) or sorted(us) != sorted(problem.input_names):
        pairs = ", ".join(f"{y}-{u}" for y, u in zip(ys, us, strict=True))
        raise CosimError(f"controller 'pi': loops must pair each output "
                         f"({', '.join(problem.output_names)}) with one input "
                         f"({', '.join(problem.input_names)}), got {pairs}")
    return tuple(out)


def _initial_inputs(values: Any, problem: ControlProblem) -> dict[str, float]:
    """Check the ``initial_inputs`` option: plant input name → finite number."""
    if values is None:
        return {}
    return _by_name("initial_inputs", values, problem.input_names, "input")


def _by_name(option: str, values: Any, names: Sequence[str], kind: str) -> dict[str, float]:
    """The option ``option``: a map of the problem's ``kind`` signals (``names``) to finite
    numbers."""
    if not isinstance(values, Mapping):
        raise CosimError(f"controller 'pi': {option} must map {kind}s to numbers, "
                         f"got {values!r}")
    out = {}
    for name, value in values.items():
        if name not in names:
            raise CosimError(f"controller 'pi': {option}: unknown {kind} {name!r} "
                             f"({kind}s: {', '.join(names)})")
        if (isinstance(value, bool) or not isinstance(value, int | float)
                or not math.isfinite(value)):
            raise CosimError(f"controller 'pi': {option}: {name} must be a finite "
                             f"number, got {value!r}")
        out[name] = float(value)
    return out


def _feedforward(option: Any, gru: GRUModel | None, problem: ControlProblem,
                 tuning: PITuning | None) -> tuple[np.ndarray, np.ndarray] | None:
    """The feedforward's ``(K_ff, d_0)`` in physical units, or ``None`` when off."""
    if option is not None and not isinstance(option, bool):
        raise CosimError(f"controller 'pi': feedforward must be true or false, got {option!r}")
    if not problem.disturbances or option is False or (option is None and gru is None):
        if option and not problem.disturbances:
            raise CosimError(f"controller 'pi': feedforward=true, but the problem "
                             f"{problem.name!r} measures no disturbances")
        return None
    if gru is None:
        raise CosimError("controller 'pi': feedforward=true needs a model (--model FILE)")
    from controllers.errors import ControllersError

    full = gru if gru.problem is not None else replace(gru, problem=problem)
    try:
        x, u, _ = pi_tuning.operating_point(
            condition(full), None if tuning is None else tuning.y_op)
        gain = feedforward_gain(full, x, np.concatenate([u, np.zeros(problem.q)]))
    except (ControllersError, np.linalg.LinAlgError) as exc:
        raise CosimError(f"controller 'pi': no feedforward from {gru.source or 'the model'}: "
                         f"{exc}") from None
    u_scale = np.asarray(full.u_scale, dtype=float)
    m = problem.m
    physical = gain * u_scale[:m, None] / u_scale[None, m:]
    return physical, np.array([c.offset for c in problem.disturbances])


class PIController(Component):
    """Decentralised PI with anti-windup and input saturation (see the module docstring).

    Parameters
    ----------
    problem : ControlProblem or path, optional
        The control problem or its file (default: the model's, else the default plant's).
    model : GRUModel or path, optional
        A model (file): its problem is the default; the loops are tuned from it when the
        problem has no ``[pi]`` loops.
    pairing : str, optional
        One of the problem's named pairings (default: its ``pairing``).
    loops : list, optional
        The loops themselves, each ``{"output", "input", "K", "Ti", "Tt"}`` (or
        :class:`~controllers.problem.PILoop`); instead of a pairing.
    initial_inputs : dict, optional
        Inputs at the first step (integrator initial values); default mid-range.
    tune : bool, optional
        Tune the loops from ``model`` (:mod:`controllers.pi_tuning`) even when the problem
        has ``[pi]`` loops; ``False``: never. Default: when the problem has none and a model
        is given.
    tune_setpoint : dict, optional
        Outputs of the operating point the loops are tuned at (physical units; outputs not
        named: the middle of their box, the default for all).
    tune_tau_c : float, optional
        SIMC closed-loop time constant of every tuned loop [s] (default: each loop's
        delay ``θ``); larger is slower and more robust.
    feedforward : bool, optional
        The static feedforward from the measured disturbances (module docstring); default:
        on when the problem has disturbances and a model is given.

    Attributes
    ----------
    loops : tuple of PILoop
    tuning : PITuning or None
        The auto-tuning's record, when the loops were tuned from the model.
    """

    direct_feedthrough = True
    capabilities = frozenset({Capability.DISTURBANCES, Capability.OPERATOR})

    def __init__(self, problem: ControlProblem | str | Path | None = None,
                 model: GRUModel | str | Path | None = None, pairing: str | None = None,
                 loops: Sequence[Any] | None = None,
                 initial_inputs: Mapping[str, float] | None = None,
                 tune: bool | None = None, tune_setpoint: Mapping[str, float] | None = None,
                 tune_tau_c: float | None = None, feedforward: bool | None = None) -> None:
        from cosim.adapters.problems import problem_for

        self.name = "pi"
        gru = model if isinstance(model, GRUModel) else None
        if model is not None and gru is None:
            from controllers.errors import ControllersError

            try:
                gru = GRUModel.load(model)
            except ControllersError as exc:
                raise CosimError(str(exc)) from None
        self.problem = problem = problem_for(gru, problem)
        if problem.m != problem.p:
            raise CosimError(f"controller 'pi': the problem {problem.name!r} has "
                             f"{problem.m} inputs and {problem.p} outputs; a decentralised PI "
                             "needs as many inputs as outputs (use the robust MPC)")
        if tune is not None and not isinstance(tune, bool):
            raise CosimError(f"controller 'pi': tune must be true or false, got {tune!r}")
        if tune is None:
            tune = loops is None and pairing is None and not problem.pairings and gru is not None
        self.tuning: PITuning | None = None
        if tune:
            if loops is not None or pairing is not None:
                raise CosimError("controller 'pi': give tune or loops/pairing, not both")
            if gru is None:
                raise CosimError("controller 'pi': tune=true needs a model to tune from "
                                 "(--model FILE or --option model=FILE)")
            self.tuning = _tuned(gru, problem, tune_setpoint, tune_tau_c)
            self.loops = self.tuning.pi_loops()
        else:
            if tune_setpoint is not None or tune_tau_c is not None:
                raise CosimError("controller 'pi': tune_setpoint and tune_tau_c apply only "
                                 "to loops tuned from a model (tune=true)")
            self.loops = _loops(problem, pairing, loops)
        self.sample_time = problem.Ts
        self.bounds = problem.bounds()
        self.inputs = tuple(Signal(c.name, c.unit, c.description) for c in problem.outputs) + \
            tuple(Signal(f"ref.{c.name}", c.unit, f"set-point of {c.name}")
                  for c in problem.outputs)
        self.outputs = tuple(Signal(c.name, c.unit, c.description) for c in problem.inputs)
        self.initial_inputs = _initial_inputs(initial_inputs, problem)
        self.feedforward = _feedforward(feedforward, gru, problem, self.tuning)
        if self.feedforward is not None:
            self.inputs += tuple(Signal(f"dist.{c.name}", c.unit, c.description)
                                 for c in problem.disturbances)
        self.disturbance_defaults = {c.name: c.offset for c in problem.disturbances}
        self._values: dict[str, float] = {}
        from controllers.operator import Operator

        #: the operator's settings (:mod:`controllers.operator`)
        self.operator = Operator(problem, "pi", no_output_limits=(
            "the PI baseline constrains no output (its loops track set-points only)"))
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        """Reset integrators to the initial inputs."""
        self._I = {}
        for loop in self.loops:
            lo, hi = self.bounds[loop.u]
            self._I[loop.u] = self.initial_inputs.get(loop.u, 0.5 * (lo + hi))
        self._u = dict(self._I)
        self._computed = dict(self._I)
        self._sat_steps = dict.fromkeys(self._u, 0)
        self._steps = 0
        self.operator.reset()

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Measured outputs and set-points (``ref.<y>``)."""
        self._values.update(values)

    def step(self, t: float, dt: float) -> None:
        """One PI update per loop; ``dt`` is the sample interval."""
        vals = self._values
        ff = self._feedforward(vals)
        if self.operator.engaged:
            self._operated_step(vals, ff, dt)
            return
        for loop in self.loops:
            e = vals[f"ref.{loop.y}"] - vals[loop.y]
            v = self._I[loop.u] + loop.K * e + ff.get(loop.u, 0.0)
            lo, hi = self.bounds[loop.u]
            u = hi if v > hi else lo if v < lo else v
            if u != v:
                self._sat_steps[loop.u] += 1
            self._I[loop.u] += loop.K * dt / loop.Ti * e + dt / loop.Tt * (u - v)
            self._u[loop.u] = u
        self._steps += 1
        self._computed = dict(self._u)
        self.operator.last = np.array([self._u[u] for u in self.problem.input_names])

    def _operated_step(self, vals: Mapping[str, float], ff: dict[str, float],
                       dt: float) -> None:
        """One update under the operator's settings (module docstring): each loop's
        saturated output, the inputs the plant gets (:meth:`controllers.operator.Operator.
        applied`; an opened loop's input held), the integrators back-calculated."""
        op, names = self.operator, list(self.problem.input_names)
        start = np.array([self._u[u] for u in names])
        box = op.input_box(start)
        e, v, computed = {}, {}, np.empty(len(names))
        for loop in self.loops:
            j = names.index(loop.u)
            e[loop.u] = vals[f"ref.{loop.y}"] - vals[loop.y]
            v[loop.u] = self._I[loop.u] + loop.K * e[loop.u] + ff.get(loop.u, 0.0)
            computed[j] = min(max(v[loop.u], box[j, 0]), box[j, 1])
        opened = {lp.u for lp in self.loops
                  if not op.control[self.problem.output_names.index(lp.y)]}
        hold = np.array([u in opened for u in names])
        applied = op.applied(np.where(hold, start, computed), start)
        for loop in self.loops:
            j, u = names.index(loop.u), loop.u
            if applied[j] != v[u]:
                self._sat_steps[u] += 1
            if op.writing[j] and not hold[j]:   # anti-windup towards the input applied
                self._I[u] += loop.K * dt / loop.Ti * e[u] + dt / loop.Tt * (applied[j] - v[u])
            else:   # tracking: the integrator that gives the input applied (bumpless)
                self._I[u] = applied[j] - loop.K * e[u] - ff.get(u, 0.0)
            self._u[u], self._computed[u] = float(applied[j]), float(computed[j])
        self._steps += 1

    def settings(self) -> dict[str, Setting]:
        """The operator's settings (:meth:`controllers.operator.Operator.settings`)."""
        units = self.problem.units()
        return {name: Setting(name, lo, hi, text, value,
                              units.get(name.split(".")[-1], "") if name.startswith(
                                  ("op.min", "op.max", "op.manual")) else "", role="operator")
                for name, lo, hi, text, value in self.operator.settings()}

    def set(self, name: str, value: float) -> str:
        """An operator's setting from the next step on; refused in the user's words."""
        why = self.operator.refuse(name, value)
        if why:
            raise CosimError(f"controller 'pi': {name}={value!r}: {why}")
        return f"{name} = {float(value):g}: {self.operator.set(name, value)}"

    def _feedforward(self, vals: Mapping[str, float]) -> dict[str, float]:
        """``K_ff (d − d_0)`` by input (physical units); empty without feedforward."""
        if self.feedforward is None:
            return {}
        gain, d0 = self.feedforward
        d = [vals[f"dist.{c.name}"] for c in self.problem.disturbances]
        du = gain @ (np.asarray(d) - d0)
        return dict(zip(self.problem.input_names, du.tolist(), strict=True))

    def get_outputs(self) -> dict[str, float]:
        """Inputs to apply (the problem's units)."""
        return dict(self._u)

    def diagnostics(self) -> dict[str, float]:
        """Integrator states ``int_<u>`` [input units] and what the loops computed,
        ``computed.<u>``."""
        return {**{f"int_{u}": i for u, i in self._I.items()},
                **{f"computed.{u}": c for u, c in self._computed.items()}}

    def summary(self) -> dict:
        """Loop pairing, gains, whether they were tuned from the model (then the tuning's
        record: operating point, gain matrix, RGA, each loop's fit) and how often each input
        saturated."""
        doc = {"pairing": {lp.y: lp.u for lp in self.loops},
               "loops": [lp.to_dict() for lp in self.loops],
               "auto_tuned": self.tuning is not None,
               "feedforward": None if self.feedforward is None else {
                   "gain": self.feedforward[0].tolist(),
                   "inputs": list(self.problem.input_names),
                   "disturbances": list(self.problem.disturbance_names)}}
        if self.tuning is not None:
            doc["tuning"] = self.tuning.to_dict()
        return {**doc, "steps": self._steps, "saturated_steps": dict(self._sat_steps),
                "operator": {"final": self.operator.summary()}}
