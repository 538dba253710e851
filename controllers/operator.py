"""What an operator may change on a running controller, checked, and what it imposes on the
controller's steps (issue 61; docs: guide/operating.md, design/operating.md).

Every advanced-process-control product gives its operators a handful of switches; these are
this project's, by name (one name everywhere: scenario columns, the faceplate's nodes, the
audit log ``operator.csv``, the controller FMU's inputs):

``op.mode``
    ``1`` auto (today's behaviour), ``0`` manual: the controller writes the operator's
    inputs; its observer and its law keep running on them (shadow), and what it would have
    written is recorded beside them.
``op.service.<input>``
    ``1`` / ``0``: an input out of service is held at the plant's value (the last applied)
    and enters the law as a known input; the others keep controlling; all out is manual.
``op.manual.<input>``
    The operator's value of an input in manual (problem units, inside its box); unset
    (``NaN``): the value the plant has (the last applied; before any, the model's
    equilibrium input of the first measured output: the plant at rest).
``op.control.<output>``
    ``1`` / ``0``: an output not controlled leaves the cost; its constraints stay.
``op.min.<signal>``, ``op.max.<signal>``
    Operator limits of an input or an output, inside the problem's box (the engineer's):
    the *target*; the *active* limit ramps towards a narrower target (:meth:`Operator.ramp`:
    an input's by at most its ``max_move`` per sample, an output's by at most its
    ``limit_rate`` and never past what the present plan needs) and follows a wider one at
    once.

:class:`Operator` holds one controller's settings over a run: :meth:`Operator.refuse`
(why a value is refused, the setting kept), :meth:`Operator.set`, and each step the inputs
the plant gets (:meth:`Operator.applied`: manual, held, limited, and never more than
``max_move`` from the last) and the bounds the law's problem gets
(:meth:`Operator.terms`, :class:`controllers.ocp.operator_terms.OperatorTerms`). What the
certificate makes of the settings is the controller's (:meth:`controllers.mpc.RobustMPC.
operate`); the co-simulation's one checked entry for scenario rows, the faceplate and a web
page is :class:`cosim.core.operator.OperatorDesk`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["AUTO", "MANUAL", "PREFIX", "Operator", "row_narrowing"]

#: The prefix of every operator setting.
PREFIX = "op."
#: ``op.mode``'s values (the words ``auto`` and ``manual`` of scenario cells and the
#: faceplate are :data:`cosim.core.operator.MODE_WORDS`).
AUTO, MANUAL = 1.0, 0.0
#: The families of ``op.<family>.<signal>``, with the signals they take.
_FAMILIES = {"service": "inputs", "manual": "inputs", "control": "outputs",
             "min": "signals", "max": "signals"}


def row_narrowing(L: np.ndarray, h: np.ndarray, lo: np.ndarray, hi: np.ndarray
                  ) -> np.ndarray:
    """``δ ≥ 0`` of the rows ``L y ≤ h`` (normalised outputs) under the operator's box
    ``lo ≤ y ≤ hi`` (normalised, ``±inf``: none): a row bounding one output by ``±y_j`` is
    narrowed to the operator's bound (``eq:operator-rows``); any other row is kept."""
    out = np.zeros(h.shape[0])
    for r, row in enumerate(L):
        nz = np.flatnonzero(row)
        if nz.size != 1:
            continue
        j, c = int(nz[0]), float(row[nz[0]])
        bound = c * (hi[j] if c > 0 else lo[j])
        if math.isfinite(bound):
            out[r] = max(0.0, float(h[r]) - bound)
    return out


class Operator:
    """One controller's operator settings over a run (module docstring).

    Parameters
    ----------
    problem : ControlProblem
        The inputs and outputs, their boxes, ``max_move`` and ``limit_rate``.
    name : str
        The controller's name (messages).
    no_output_limits : str
        Why the controller takes no operator limit on its outputs (``""``: it does; the
        PI baseline constrains no output).
    no_dropping : str
        Why an output cannot leave its cost (``op.control``; ``""``: it can).
    """

    def __init__(self, problem: Any, name: str = "controller", *,
                 no_output_limits: str = "", no_dropping: str = "") -> None:
        self.problem = problem
        self.name = name
        self.inputs = list(problem.input_names)
        self.outputs = list(problem.output_names)
        self.u_box = np.array([c.bounds for c in problem.inputs], dtype=float).reshape(-1, 2)
        self.y_box = np.array([c.bounds for c in problem.outputs], dtype=float).reshape(-1, 2)
        width = self.u_box[:, 1] - self.u_box[:, 0]
        #: the move limit per input (problem units; the box width where none is declared)
        self.max_move = np.array([width[j] if c.max_move is None else c.max_move
                                  for j, c in enumerate(problem.inputs)])
        #: whether any input declares one (the move limit is then part of every step)
        self.moves = any(c.max_move is not None for c in problem.inputs)
        self.limit_rate = np.array([math.inf if c.limit_rate is None else c.limit_rate
                                    for c in problem.outputs])
        self.no_output_limits, self.no_dropping = no_output_limits, no_dropping
        self.outputs_limited = not no_output_limits
        self.drops_outputs = not no_dropping
        self.reset()

    def reset(self) -> None:
        """A new run: auto, everything in service and controlled, no operator limit."""
        m, p = len(self.inputs), len(self.outputs)
        self.mode = AUTO
        self.service = np.ones(m, dtype=bool)
        self.manual = np.full(m, math.nan)
        self.control = np.ones(p, dtype=bool)
        #: the operator's limits asked for (targets) and in force (active), problem units
        self.u_target, self.u_active = self.u_box.copy(), self.u_box.copy()
        self.y_target, self.y_active = self.y_box.copy(), self.y_box.copy()
        #: the inputs the plant got last (problem units; ``None`` before the first step)
        self.last: np.ndarray | None = None

    # -- the settings ------------------------------------------------------------------------
    def names(self) -> list[str]:
        """Every setting's name, in a fixed order."""
        out = ["op.mode"]
        out += [f"op.{f}.{u}" for f in ("service", "manual") for u in self.inputs]
        if self.drops_outputs:
            out += [f"op.control.{y}" for y in self.outputs]
        signals = self.inputs + (self.outputs if self.outputs_limited else [])
        out += [f"op.{f}.{s}" for f in ("min", "max") for s in signals]
        return out

    def settings(self) -> list[tuple[str, float, float, str, float]]:
        """``(name, low, high, description, value now)`` of each setting (:meth:`names`)."""
        return [(name, *self._range(name), self._describe(name), self.value(name))
                for name in self.names()]

    def _parse(self, name: str) -> tuple[str, str, int]:
        """``(family, signal, index)`` of a setting's name; ``("", "", -1)`` for an unknown
        one."""
        if name == "op.mode":
            return "mode", "", 0
        parts = name.split(".")
        if len(parts) != 3 or parts[0] != "op" or parts[1] not in _FAMILIES:
            return "", "", -1
        family, signal = parts[1], parts[2]
        kind = _FAMILIES[family]
        if kind in ("inputs", "signals") and signal in self.inputs:
            return family, signal, self.inputs.index(signal)
        if kind in ("outputs", "signals") and signal in self.outputs:
            return family, signal, len(self.inputs) + self.outputs.index(signal)
        return "", "", -1

    def _range(self, name: str) -> tuple[float, float]:
        family, _, k = self._parse(name)
        if family in ("min", "max", "manual"):
            return tuple(self._box(k))  # type: ignore[return-value]
        return 0.0, 1.0

    def _box(self, k: int) -> np.ndarray:
        """The engineer's box of signal ``k`` (inputs, then outputs)."""
        m = len(self.inputs)
        return self.u_box[k] if k < m else self.y_box[k - m]

    def _describe(self, name: str) -> str:
        family, signal, _ = self._parse(name)
        return {"mode": "1 auto, 0 manual (the operator's inputs; the controller in shadow)",
                "service": f"1: {signal} is written by the controller, 0: held where it is",
                "manual": f"the operator's value of {signal} in manual (unset: the plant's)",
                "control": f"1: {signal} is in the cost, 0: left free (its limits stay)",
                "min": f"operator low limit of {signal}, inside the engineer's box",
                "max": f"operator high limit of {signal}, inside the engineer's box"}[family]

    def value(self, name: str) -> float:
        """The setting's value now (an operator limit: its target)."""
        family, _, k = self._parse(name)
        m = len(self.inputs)
        if family == "mode":
            return self.mode
        if family in ("service", "manual"):
            return float(self.service[k]) if family == "service" else float(self.manual[k])
        if family == "control":
            return float(self.control[k - m])
        limits = self.u_target[k] if k < m else self.y_target[k - m]
        return float(limits[0 if family == "min" else 1])

    def refuse(self, name: str, value: float) -> str:
        """Why ``name`` cannot take ``value`` now, in the user's words (``""``: it can).
        An unknown name, a mode or switch other than 0/1, a manual value or an operator
        limit outside the engineer's box, a low limit not below the high one."""
        family, signal, k = self._parse(name)
        if not family:
            return f"no operator setting {name!r} (settings: {', '.join(self.names())})"
        if name not in self.names():
            return self.no_dropping if family == "control" else self.no_output_limits
        value = float(value)
        if family in ("mode", "service", "control"):
            if value not in (0.0, 1.0):
                return ("expected auto or manual (1 or 0)" if family == "mode"
                        else "expected 1 (in) or 0 (out)")
            return ""
        lo, hi = self._box(k)
        unit = self._unit(k)
        if family == "manual" and math.isnan(value):
            return ""
        if not (math.isfinite(value) and lo <= value <= hi):
            what = "the value" if family == "manual" else "an operator limit"
            return (f"{what} {value:g}{unit} of {signal} is outside the engineer's box "
                    f"[{lo:g}, {hi:g}]{unit}")
        if family in ("min", "max"):
            other = self.value(f"op.{'max' if family == 'min' else 'min'}.{signal}")
            low, high = (value, other) if family == "min" else (other, value)
            if not low < high:
                return (f"the operator limits of {signal} would leave nothing: low {low:g} "
                        f"not below high {high:g}{unit}")
        return ""

    def _unit(self, k: int) -> str:
        m = len(self.inputs)
        unit = (self.problem.input_units[k] if k < m else self.problem.output_units[k - m])
        return f" {unit}" if unit else ""

    def set(self, name: str, value: float) -> str:
        """Setting ``name`` to ``value`` (:meth:`refuse` has found nothing): what it does,
        in one line."""
        family, signal, k = self._parse(name)
        value = float(value)
        m = len(self.inputs)
        if family == "mode":
            self.mode = value
            return "auto: the controller writes the inputs" if value == AUTO else \
                "manual: the operator's inputs; the controller predicts in shadow"
        if family == "service":
            self.service[k] = bool(value)
            return (f"{signal} back in service: it moves from where it is" if value
                    else f"{signal} out of service: held where it is, a known input")
        if family == "manual":
            self.manual[k] = value
            return f"{signal} in manual: {value:g}" if math.isfinite(value) else \
                f"{signal} in manual: held where it is"
        if family == "control":
            self.control[k - m] = bool(value)
            return (f"{signal} controlled" if value
                    else f"{signal} not controlled: out of the cost, its limits kept")
        target = self.u_target[k] if k < m else self.y_target[k - m]
        active = self.u_active[k] if k < m else self.y_active[k - m]
        side = 0 if family == "min" else 1
        target[side] = value
        wider = value < active[side] if side == 1 else value > active[side]
        if not wider:   # a wider limit holds at once; a narrower one ramps
            active[side] = value
            return f"{family} of {signal}: {value:g} in force"
        return f"{family} of {signal}: ramping to {value:g}"

    # -- what they change --------------------------------------------------------------------
    @property
    def engaged(self) -> bool:
        """Whether anything differs from auto with the engineer's box, every input in
        service and every output controlled, or a move limit is declared: the step then
        goes through :meth:`terms` and :meth:`applied`."""
        return bool(self.moves or self.mode != AUTO or not self.service.all()
                    or not self.control.all()
                    or np.any(self.u_target != self.u_box) or np.any(self.u_active != self.u_box)
                    or np.any(self.y_target != self.y_box)
                    or np.any(self.y_active != self.y_box))

    @property
    def writing(self) -> np.ndarray:
        """The inputs the controller writes (in auto and in service)."""
        return self.service & (self.mode == AUTO)

    def held(self, start: np.ndarray) -> np.ndarray:
        """The values the inputs not written are held at (problem units): the operator's
        manual value, else the plant's (:attr:`last`; before any, ``start``)."""
        base = self.last if self.last is not None else np.asarray(start, dtype=float)
        return np.where(np.isfinite(self.manual) & (self.mode != AUTO), self.manual, base)

    def ramp(self, room: np.ndarray | None = None) -> None:
        """Move the active limits towards narrower targets: an input's by at most its
        ``max_move``, an output's by at most its ``limit_rate`` and ``room`` (p, 2: how far
        each output's low and high limit may move in with the present plan still feasible,
        problem units; ``None``: not at all this step)."""
        step = np.stack([self.max_move, self.max_move], axis=1)
        self.u_active = _towards(self.u_active, self.u_target, step)
        if self.outputs_limited:
            rate = np.stack([self.limit_rate, self.limit_rate], axis=1)
            allowed = np.zeros_like(rate) if room is None else np.minimum(rate, room)
            self.y_active = _towards(self.y_active, self.y_target, allowed)

    def input_box(self, start: np.ndarray, fixed: np.ndarray | None = None) -> np.ndarray:
        """Each input's range this step (m, 2; problem units): its active limits, the
        held value for one ``fixed`` (default: not written; the law's problem fixes only
        those out of service, :meth:`terms`: in manual it plans in shadow)."""
        box = self.u_active.copy()
        held = self.held(start)
        fixed = ~self.writing if fixed is None else fixed
        box[fixed, 0] = box[fixed, 1] = np.clip(held[fixed], self.u_box[fixed, 0],
                                                self.u_box[fixed, 1])
        return box

    def applied(self, computed: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The inputs the plant gets (problem units) for the controller's ``computed``
        ones: the operator's or the held value where it does not write; inside the active
        limits and within ``max_move`` of the last (every mode) where it does; remembered
        as :attr:`last`."""
        box = self.input_box(start)
        u = np.where(self.writing, computed, box[:, 0])
        u = np.minimum(np.maximum(u, box[:, 0]), box[:, 1])
        if self.moves and self.last is not None:
            lo, hi = self.last - self.max_move, self.last + self.max_move
            u = np.where(self.writing, np.minimum(np.maximum(u, lo), hi), u)
        self.last = np.array(u, dtype=float)
        return self.last

    def terms(self, scale: np.ndarray, offset: np.ndarray, start: np.ndarray,
              narrowing: np.ndarray) -> Any:
        """The :class:`~controllers.ocp.operator_terms.OperatorTerms` of this step
        (normalised with the inputs' ``scale`` and ``offset``): the active limits, an input
        out of service fixed at its held value (in manual the others stay free: the law
        plans in shadow), ``u_0`` within ``max_move`` of the plant's input, and the output
        rows' ``narrowing``."""
        from controllers.ocp.operator_terms import OperatorTerms

        box = (self.input_box(start, ~self.service) - offset[:, None]) / scale[:, None]
        lo, hi = np.minimum(box[:, 0], box[:, 1]), np.maximum(box[:, 0], box[:, 1])
        lo0, hi0 = lo.copy(), hi.copy()
        if self.moves and self.last is not None:
            last = (self.last - offset) / scale
            step = self.max_move / np.abs(scale)
            lo0 = np.where(self.service, np.maximum(lo0, last - step), lo0)
            hi0 = np.where(self.service, np.minimum(hi0, last + step), hi0)
        return OperatorTerms(lo0, hi0, lo, hi, np.asarray(narrowing, dtype=float))

    def last_normalised(self, scale: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """:attr:`last` normalised (``(u − offset) / scale``)."""
        assert self.last is not None, "no input applied yet"
        return (self.last - offset) / scale

    def setpoint(self, ref: np.ndarray) -> np.ndarray:
        """The set-points inside the operator's output limits (their targets: the plan
        heads inside them, and the active limits follow it there)."""
        if not self.outputs_limited:
            return ref
        return np.minimum(np.maximum(ref, self.y_target[:, 0]), self.y_target[:, 1])

    def summary(self) -> dict[str, Any]:
        """The settings at the end (``summary.json``'s ``operator.final``)."""
        return {"mode": "auto" if self.mode == AUTO else "manual",
                "out_of_service": [u for u, s in zip(self.inputs, self.service, strict=True)
                                   if not s],
                "not_controlled": [y for y, c in zip(self.outputs, self.control, strict=True)
                                   if not c],
                "limits": {s: [float(a), float(b)] for s, (a, b) in zip(
                    self.inputs + self.outputs, np.vstack([self.u_active, self.y_active]),
                    strict=True)
                    if (a, b) != tuple(self._box(self._index(s)))}}

    def _index(self, signal: str) -> int:
        return (self.inputs.index(signal) if signal in self.inputs
                else len(self.inputs) + self.outputs.index(signal))


def _towards(active: np.ndarray, target: np.ndarray, step: np.ndarray) -> np.ndarray:
    """``active`` limits (k, 2) moved towards narrower ``target`` ones by at most ``step``
    (k, 2); a target wider than the active limit is taken at once."""
    lo = np.where(target[:, 0] > active[:, 0],
                  np.minimum(target[:, 0], active[:, 0] + step[:, 0]), target[:, 0])
    hi = np.where(target[:, 1] < active[:, 1],
                  np.maximum(target[:, 1], active[:, 1] - step[:, 1]), target[:, 1])
    return np.stack([lo, hi], axis=1)

