"""The robust MPC under an operator's settings (issue 61; docs: design/operating.md): what
each setting re-derives for the law between two steps, what the plant gets, which of the
certificate's guarantees hold, and the predictions against the plant.

:class:`Operating` is the part of :class:`controllers.mpc.RobustMPC` that the operator's
settings (:class:`controllers.operator.Operator`) add; with none of them engaged (auto,
everything in service and controlled, the engineer's box, no ``max_move``) the step is the
controller's as before, to the bit. Otherwise, each step:

1. the active limits ramp (:meth:`controllers.operator.Operator.ramp`): an output's never
   past what the present plan needs at the next step (:meth:`Operating.room`: the plan's
   rows, tightened as ``eq:optimization-constraint``, and the tracking law's ``Y_s`` row of
   its steady state), so that the candidate of ``th:feasibility-stability`` stays feasible;
2. the set-point is taken to the closest output inside the active limits (named in the
   notes);
3. the FHOCP gets the operator's terms (:class:`controllers.ocp.operator_terms.
   OperatorTerms`: the input bounds, ``u_0`` within ``max_move`` of the plant's input, the
   rows' narrowing ``δ``, ``eq:operator-rows``) and the law steps (in manual: in shadow);
4. the plant gets :meth:`controllers.operator.Operator.applied`; the observer, the held
   inputs and the law continue from it (bumpless: their ``u_{−1}`` is the plant's).

A request the certificate cannot cover is refused in the user's words, the setting kept
(:meth:`Operating.operate`): operator limits that leave no admissible steady output (the
tracking law's ``Y_s`` narrowed to nothing), an output leaving the paper's law's cost, an
output limit under the paper's law (its set-point theory, Assumption 1 and ``eq:def-alpha``,
is the certificate's box).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.errors import OptionError
from controllers.operator import AUTO, Operator, row_narrowing
from controllers.shadow import PredictionWatch

__all__ = ["Operating"]

#: At most this many set-point notes in a run's summary.
MAX_NOTES = 5


class Operating:
    """The operator's part of one :class:`~controllers.mpc.RobustMPC` (module docstring)."""

    def __init__(self, mpc: Any) -> None:
        self.mpc = mpc
        pr = mpc.problem
        self.tracking = bool(mpc.law.output_limits)
        why = "" if self.tracking else (
            "the paper's law regulates to the equilibrium of every output (eq:mpc) and its "
            "set-points' theory (Assumption 1, eq:def-alpha) is the certificate's box: use "
            "law=tracking")
        self.operator = Operator(pr, mpc.name, no_output_limits=why, no_dropping=why)
        model = mpc.model
        self.u_scale = np.asarray(model.u_scale, dtype=float)[:pr.m]
        self.u_offset = np.asarray(model.u_offset, dtype=float)[:pr.m]
        self.watch = PredictionWatch(list(pr.output_names), mpc.fhocp.N)
        self.reset()

    def reset(self) -> None:
        """A new run: the operator's settings back to auto with the engineer's box."""
        if not self.operator.control.all():
            self.mpc.law.control(np.ones(self.operator.control.size, dtype=bool))
        self.operator.reset()
        self.watch.reset()
        self.start: np.ndarray | None = None   # the plant at rest (problem units)
        self.notes: list[str] = []
        self._clipped: tuple | None = None
        self.periods: list[dict[str, Any]] = []
        self.refused = 0
        self._input_ramped = False

    # -- the settings ------------------------------------------------------------------------
    def operate(self, name: str, value: float) -> str:
        """Operator setting ``name`` from the next step on (module docstring); what it
        re-derived, in one line.

        Raises
        ------
        OptionError
            A value refused (the setting unchanged), in the user's words.
        """
        op = self.operator
        why = op.refuse(name, value)
        if not why and name.startswith(("op.min.", "op.max.")):
            why = self._uncovered(name, float(value))
        if why:
            self.refused += 1
            raise OptionError(f"controller {self.mpc.name!r}: {name}={value!r}: {why}")
        if name.startswith("op.control."):
            mask = op.control.copy()
            mask[op.outputs.index(name.split(".")[2])] = bool(value)
            what = self.mpc.law.control(mask)
            op.set(name, value)
            return f"{name} = {value:g}: {what}"
        return f"{name} = {value:g}: {op.set(name, value)}"

    def _uncovered(self, name: str, value: float) -> str:
        """Why the output limit ``name`` = ``value`` (its target) is more than the
        certificate covers: the tracking law's admissible steady outputs ``Y_s`` narrowed
        to nothing (``""``: covered)."""
        op = self.operator
        signal = name.split(".")[2]
        if signal not in op.outputs:
            return ""
        box = op.y_target.copy()
        box[op.outputs.index(signal), 0 if name.startswith("op.min.") else 1] = value
        lo, hi = self._steady_box(box)
        j = op.outputs.index(signal)
        if lo[j] <= hi[j]:
            return ""
        return (f"no admissible steady output of {signal} is left inside the operator "
                f"limits (the certified steady outputs with the constraints tightened by "
                "the model's error bounds): the previous limits are kept")

    def _steady_box(self, box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per output ``(lo, hi)`` (problem units) of the tracking law's admissible steady
        outputs ``Y_s`` narrowed by the operator's output box ``box`` (p, 2)."""
        model, fh = self.mpc.model, self.mpc.fhocp
        lo_n, hi_n = _interval(fh.L, fh.reference.ys_base - self._narrowing(box))
        b_o = fh.params["b_o"]
        scale, offset = np.asarray(model.y_scale), np.asarray(model.y_offset)
        a, b = (lo_n + b_o) * scale + offset, (hi_n + b_o) * scale + offset
        return np.where(scale > 0, a, b), np.where(scale > 0, b, a)   # lo > hi: empty

    def _admissible(self, ref: np.ndarray) -> np.ndarray:
        """The set-points of the outputs whose operator limits are narrowed taken inside the
        admissible steady outputs under those limits (the closest admissible output)."""
        op = self.operator
        narrowed = np.any(op.y_target != op.y_box, axis=1)
        if not self.tracking or not narrowed.any():
            return ref
        lo, hi = self._steady_box(op.y_target)
        return np.where(narrowed, np.minimum(np.maximum(ref, lo), hi), ref)

    def _narrowing(self, box: np.ndarray) -> np.ndarray:
        """``δ`` of the output rows for the operator's output box (p, 2; problem units)."""
        model, fh = self.mpc.model, self.mpc.fhocp
        a = (box - np.asarray(model.y_offset)[:, None]) / np.asarray(model.y_scale)[:, None]
        lo, hi = np.minimum(a[:, 0], a[:, 1]), np.maximum(a[:, 0], a[:, 1])
        return row_narrowing(fh.L, fh.h, lo, hi)

    # -- each step ---------------------------------------------------------------------------
    def before(self, ref: np.ndarray, t: float) -> np.ndarray:
        """Ramp the limits, give the FHOCP the operator's terms; the set-point inside the
        active output limits (step 1–3 of the module docstring)."""
        op, mpc = self.operator, self.mpc
        if not op.engaged:
            mpc.fhocp.set_operator(None)
            return ref
        if op.last is None and self.start is None:   # the plant at rest
            self.start = self._rest()
        before = op.u_active.copy()
        op.ramp(self.room())
        self._input_ramped = not np.array_equal(before, op.u_active)
        inside = self._admissible(op.setpoint(ref))
        self._note(ref, inside, t)
        mpc.fhocp.set_operator(op.terms(self.u_scale, self.u_offset, self.start,
                                        self._narrowing(op.y_active)))
        return inside

    def after(self, u_norm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(applied, applied normalised)``: what the plant gets for the law's ``u_norm``
        (step 4)."""
        mpc = self.mpc
        computed = np.clip(mpc.model.denormalize_u(u_norm), mpc.u_lo, mpc.u_hi)
        applied = self.operator.applied(computed, self.start)
        un = (applied - self.u_offset) / self.u_scale
        mpc.law.applied(un)
        return applied, un

    def _rest(self) -> np.ndarray:
        """The plant's inputs before the first step: the model's equilibrium input of the
        first output estimate (the plant at rest; the dead time's assumption too)."""
        from controllers.equilibrium import equilibrium_for_output

        mpc = self.mpc
        _, u0 = equilibrium_for_output(mpc.model.params, mpc.observer.y_hat(),
                                       mpc.fhocp.kernel)
        return np.clip(mpc.model.denormalize_u(np.clip(u0, -1.0, 1.0)), mpc.u_lo, mpc.u_hi)

    def _note(self, ref: np.ndarray, inside: np.ndarray, t: float) -> None:
        """Name a set-point taken inside the operator's limits, once per change."""
        key = (tuple(ref), tuple(inside))
        if np.array_equal(ref, inside) or key == self._clipped:
            self._clipped = None if np.array_equal(ref, inside) else key
            return
        self._clipped = key
        if len(self.notes) < MAX_NOTES:
            pr = self.mpc.problem
            moved = ", ".join(f"{n} {a:.4g} -> {b:.4g}{(' ' + u) if u else ''}"
                              for n, a, b, u in zip(pr.output_names, ref, inside,
                                                    pr.output_units, strict=True) if a != b)
            self.notes.append(f"from t = {t:g} s the set-point is beyond the operator's "
                              f"limits: taken to the closest admissible output ({moved})")

    def room(self) -> np.ndarray | None:
        """How far each output's low and high limit may move in (p, 2; problem units) with
        the candidate still feasible at the next step: the last plan's own slack in its
        rows ``L (U_o x_i + b_o) ≤ h − δ − a_i ê_o − b_i − w_L`` (``i = 1 … N−1``, at the
        plan's ``ê_o``; the chain of ``th:feasibility-stability``'s proof carries it to the
        candidate's stage ``i − 1``) and in ``Y_s`` (the tracking law's steady state);
        ``None`` after a fallback (no ramp); unlimited in manual (the plan drives
        nothing)."""
        mpc = self.mpc
        recs = mpc.law.records
        if self.operator.mode != AUTO:
            return np.full((mpc.problem.p, 2), math.inf)
        if not self.tracking or not recs or recs[-1].fallback or recs[-1].result.x is None:
            return None
        fh, rec = mpc.fhocp, recs[-1]
        x, N = np.asarray(rec.result.x), fh.N
        bounds = fh.tightened_bounds(rec.e_o)   # as the plan was solved: δ then in force
        slack = (np.min((bounds[1:N] + fh.Lbo) - self._outputs(x[1:N]) @ fh.L.T, axis=0)
                 if N > 1 else np.full(fh.q, np.inf))
        x_s = mpc.law.steady_state
        if x_s is not None:
            ys = (fh.reference.ys_rhs + fh.Lbo) - fh.L @ self._outputs(x_s[None])[0]
            slack = np.minimum(slack, ys)
        return self._room_phys(np.maximum(slack, 0.0))

    def _outputs(self, x: np.ndarray) -> np.ndarray:
        """``U_o x_i + b_o`` of the states ``x`` (rows): the compiled kernel's when there
        is one (the exported controller's sums, to the bit), else numpy's."""
        fh = self.mpc.fhocp
        if fh.kernel is not None:
            return np.array([fh.kernel.output(xi) for xi in x]).reshape(-1, fh.p)
        P = fh.params
        return x @ P["U_o"].T + P["b_o"]

    def _room_phys(self, slack: np.ndarray) -> np.ndarray:
        """Rows' slack (q,; normalised) as each output's room (p, 2; problem units)."""
        model, fh = self.mpc.model, self.mpc.fhocp
        p = fh.p
        room = np.full((p, 2), math.inf)
        scale = np.abs(np.asarray(model.y_scale, dtype=float))
        for r, row in enumerate(fh.L):
            nz = np.flatnonzero(row)
            if nz.size != 1:
                continue
            j = int(nz[0])
            side = 1 if (row[j] > 0) == (model.y_scale[j] > 0) else 0
            room[j, side] = min(room[j, side], slack[r] / abs(row[j]) * scale[j])
        return room

    def record(self, step: Any, y: np.ndarray, u_applied: np.ndarray, x0: np.ndarray,
               t: float) -> None:
        """The step's prediction of the outputs for the shadow's errors (the plan's from
        ``x0``; in manual, or after a fallback, the inputs the plant got, ``u_applied``
        normalised, held) and the period of settings it belongs to."""
        mpc = self.mpc
        self.watch.measure(y)
        rec = step.record
        x = rec.result.x
        if self.operator.mode != AUTO or rec.fallback or x is None:
            x = mpc.fhocp.simulate(x0, np.tile(u_applied, (mpc.fhocp.N, 1)))
        P = mpc.model.params
        pred = mpc.model.denormalize_y(np.asarray(x)[1:] @ P["U_o"].T + P["b_o"])
        names = mpc.problem.output_names
        d = np.array([step.diagnostics.get(f"d_hat_{n}", 0.0) for n in names])
        self.watch.predict(pred + d)
        self._period(step, t)

    def _period(self, step: Any, t: float) -> None:
        """Count the step in the period of the settings now (a new period when they
        change): its steps, softened steps and fallbacks."""
        key = self._settings_key()
        if not self.periods or self.periods[-1]["key"] != key:
            self.periods.append({"key": key, "from": t, "steps": 0, "softened_steps": 0,
                                 "fallbacks": 0, "input_ramps": 0})
        period = self.periods[-1]
        period["to"] = t
        period["steps"] += 1
        period["softened_steps"] += int(step.diagnostics.get("softened", 0.0) > 1e-9)
        period["fallbacks"] += int(step.record.fallback)
        period["input_ramps"] += int(self._input_ramped)
        self._input_ramped = False

    def _settings_key(self) -> tuple:
        op = self.operator
        return (op.mode, tuple(op.service), tuple(op.control),
                tuple(np.asarray(op.u_target).ravel()), tuple(np.asarray(op.y_target).ravel()))

    # -- the summary -------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """``operator``: the settings at the end, the refused requests, the set-point notes,
        the shadow's prediction errors and, per period of settings, which of the
        certificate's guarantees held (:func:`guarantees`)."""
        certified = bool(self.mpc.certification.certified)
        return {"final": self.operator.summary(), "refused": self.refused,
                "notes": list(self.notes), "prediction_error": self.watch.summary(),
                "periods": [guarantees(p, self.operator, certified) for p in self.periods]}


def guarantees(period: dict[str, Any], op: Operator, certified: bool) -> dict[str, Any]:
    """One period of settings with the guarantees of ``th:feasibility-stability`` that
    held under them (docs: design/operating.md, "Inputs out of service, outputs not
    controlled, manual")."""
    mode, service, control = period["key"][:3]
    inputs = [u for u, s in zip(op.inputs, service, strict=True) if not s]
    dropped = [y for y, c in zip(op.outputs, control, strict=True) if not c]
    held = []
    if not certified:
        held.append("uncertified run: no guarantee claimed (the measured tightening only)")
    elif mode != AUTO:
        held.append("manual: the operator drives the plant; the observer's bound "
                    "(eq:eo-evolution) holds, nothing else is claimed")
    else:
        clean = period["softened_steps"] == 0 and period["fallbacks"] == 0
        held.append("constraints (eq:optimization-constraint, with the operator's limits) "
                    + ("held at every step" if clean else
                       f"not claimed at {period['softened_steps'] + period['fallbacks']} "
                       "softened or fallback steps"))
        held.append("recursive feasibility: " + (
            "the candidate stayed feasible (output limits ramped within the plan)"
            if clean and not inputs and not period["input_ramps"] else
            "not claimed from the change on (an input held, an input limit ramping, or a "
            "step without an answer of the hard problem)"))
        held.append("convergence: " + ("claimed" if not dropped and not inputs else
                                       "not claimed for " + ", ".join(dropped + inputs)))
    return {"from": period["from"], "to": period["to"], "steps": period["steps"],
            "mode": "auto" if mode == AUTO else "manual", "out_of_service": inputs,
            "not_controlled": dropped, "softened_steps": period["softened_steps"],
            "fallbacks": period["fallbacks"], "guarantees": held}


def _interval(L: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per output ``(lo, hi)`` of the box rows ``L y ≤ rhs`` (normalised)."""
    p = L.shape[1]
    lo, hi = np.full(p, -np.inf), np.full(p, np.inf)
    for row, b in zip(L, rhs, strict=True):
        nz = np.flatnonzero(row)
        if nz.size == 1:
            j = int(nz[0])
            if row[j] > 0:
                hi[j] = min(hi[j], b / row[j])
            else:
                lo[j] = max(lo[j], b / row[j])
    return lo, hi
