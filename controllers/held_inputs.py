"""What the robust MPC's model sees of its measured disturbances and of the inputs it applied:
the disturbances held in the model's biases, the dead time predicted over.

:class:`HeldInputs` is the part of :class:`controllers.mpc.RobustMPC` that a problem with
measured disturbances (``[disturbances]``) or dead time (``delay``) adds:

- the design's model: the full model (inputs and disturbances) with the disturbances held in
  its biases (:func:`controllers.disturbances.condition`), moved to the measured value each
  step (:class:`controllers.disturbances.BiasShift`) before the observer and the FHOCP use
  them (:meth:`HeldInputs.hold`); when they move, the law's steady state moves with them;
- the dead times ``K_j`` of the inputs and each disturbance's ``L``: the last ``max K_j``
  inputs applied and the last ``max L + 1`` disturbances measured, ``x̂`` predicted over the
  shortest dead time ``K`` before the FHOCP starts (:meth:`HeldInputs.ahead`), the FHOCP's
  first inputs of an input whose dead time is longer fixed to those it applied
  (:attr:`HeldInputs.prefix`), the observer's step with the model input as the model sees it
  (:meth:`HeldInputs.model_input`);
- a disturbance known ahead (``preview = true``): its values to come from the run's schedule
  (:meth:`HeldInputs.set_schedule`, the scenario's ``dist.<name>`` column), used over the
  inputs' dead time, and held by the FHOCP at the value it will have when the first
  decision acts (``d_{k+K−L}``) instead of ``d_k``.

The exported controller's C step does the same in the same order (``controllers/kernel/
controller.c``: hold, ahead), to the bit. Docs: design/disturbances.md.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from controllers.errors import StepInputError

__all__ = ["HeldInputs"]


class HeldInputs:
    """The measured disturbances and dead time of one robust MPC (module docstring).

    Parameters
    ----------
    name : str
        The controller's name (messages).
    model : GRUModel
        The full model, with its problem.

    Attributes
    ----------
    model : GRUModel
        The model the controller designs on: ``model`` itself, or the one holding the
        disturbances in its biases.
    shift : BiasShift or None
        Moves those biases (None without disturbances).
    dead_time : int
        The inputs' shortest dead time ``K`` [samples]: the steps predicted before the FHOCP.
    prefix : InputPrefix
        The FHOCP's inputs already applied (inputs whose dead time exceeds ``K``), given to
        the FHOCP (:attr:`controllers.ocp.fhocp.FHOCP.prefix`) and set each step.
    clipped : int
        Steps whose measured disturbance left its box (held at the edge).
    preview : (q,) bool array
        The disturbances known ahead (``preview = true``).
    preview_held : int
        Steps one known ahead was held at its measured value instead, no schedule of it
        being given (a run whose scenario does not set it, a host stepping the controller
        itself).
    """

    def __init__(self, name: str, model: Any) -> None:
        from controllers.dead_time import InputPrefix, input_delay, input_lags
        from controllers.disturbances import BiasShift, condition

        pr = model.problem
        self.name = name
        self.dead_time = input_delay(pr)
        self.delays = np.array([c.delay for c in pr.inputs], dtype=int)
        self.depth = int(self.delays.max(initial=0))
        self.prefix = InputPrefix(input_lags(pr))
        self.lags = np.array([c.delay for c in pr.disturbances], dtype=int)
        self.preview = np.array([c.preview for c in pr.disturbances], dtype=bool)
        self.Ts = float(model.Ts)
        self.model, self.shift = model, None
        if pr.disturbances:
            self.model = condition(model)
            self.shift = BiasShift(model, self.model.params)
        self.names = [f"dist.{c.name}" for c in pr.disturbances]
        self._offset = np.array([c.offset for c in pr.disturbances])
        self._scale = np.array([c.scale for c in pr.disturbances])
        self._units = [c.unit for c in pr.disturbances]
        self.reset()

    def reset(self) -> None:
        """A new run: the nominal biases (the kernel is built and found for them), no past."""
        if self.shift is not None:
            self.shift.set(np.zeros(self.shift.q))
        self.clipped = self.preview_held = 0
        #: the values to come of those known ahead (a run's own: :meth:`set_schedule`)
        self._schedule: dict[str, Callable[[float], float]] | None = None
        #: the disturbances the FHOCP held last, and holds this step; the last ``max L + 1``
        #: measured (oldest first); the last ``max K_j`` inputs applied (normalised, oldest
        #: first); the time of the step
        self._d_law: np.ndarray | None = None
        self._d_fhocp: np.ndarray | None = None
        self._t = 0.0
        self._d_past: np.ndarray | None = None
        self._u_past: np.ndarray | None = None

    # -- each step, in this order ------------------------------------------------------------
    def measure(self, d_phys: np.ndarray, t: float, fhocp: Any) -> str:
        """Read the measured disturbances ``d_phys`` (the problem's units; normalised, each
        held inside its box) and hold them for the FHOCP (:meth:`hold`): what moved (the
        values in the user's names and units, for the law's messages), else ``""``.

        Raises
        ------
        StepInputError
            A disturbance that is not finite.
        """
        d_phys = np.asarray(d_phys, dtype=float)
        if not np.all(np.isfinite(d_phys)):
            text = ", ".join(f"{n}={v:g}" for n, v in zip(self.names, d_phys, strict=True))
            raise StepInputError(f"controller {self.name!r}: non-finite measured disturbance "
                                 f"at t={t:g} s ({text})")
        d = (d_phys - self._offset) / self._scale
        if np.any(np.abs(d) > 1.0):
            self.clipped += 1
            d = np.clip(d, -1.0, 1.0)
        depth = int(self.lags.max(initial=0)) + 1
        self._d_past = (np.tile(d, (depth, 1)) if self._d_past is None
                        else np.vstack([self._d_past[1:], d]))
        self._t = t
        self._d_fhocp = d
        if self.preview.any():   # known ahead: the value when the first decision acts
            if self._schedule is None or any(
                    n[len("dist."):] not in self._schedule
                    for n, p in zip(self.names, self.preview, strict=True) if p):
                self.preview_held += 1
            self._d_fhocp = np.array([self._value(j, max(self.dead_time - int(L), 0))
                                      for j, L in enumerate(self.lags)])
        return self.hold(self._d_fhocp, fhocp, law=True)

    def set_schedule(self, schedule: Mapping[str, Callable[[float], float]] | None) -> None:
        """The values to come of the disturbances known ahead, for this run (after
        :meth:`reset`): ``schedule[name](t)``, the value (the problem's units) set on the
        plant at ``t`` (the master gives the scenario's); one without an entry (or
        ``None``: all) is held at its measured value (counted in :attr:`preview_held`)."""
        self._schedule = None if schedule is None else dict(schedule)

    def _value(self, j: int, offset: int) -> float:
        """Disturbance ``j`` ``offset`` samples from now (normalised): measured for
        ``offset ≤ 0``; later, the schedule's for one known ahead (held inside its box),
        else its value now."""
        if offset <= 0:
            return float(self._d_past[-1 + offset, j])
        name = self.names[j][len("dist."):]
        if not self.preview[j] or self._schedule is None or name not in self._schedule:
            return float(self._d_past[-1, j])
        t = self._t + offset * self.Ts
        v = float(self._schedule[name](t))
        if not np.isfinite(v):
            raise StepInputError(f"controller {self.name!r}: the schedule of disturbance "
                                 f"{name!r} is not finite at t={t:g} s")
        return float(np.clip((v - self._offset[j]) / self._scale[j], -1.0, 1.0))

    def hold(self, d: np.ndarray, fhocp: Any, law: bool = False) -> str:
        """Hold the disturbances at ``d`` (normalised) in the model's biases, the FHOCP's and
        the observer's (the compiled kernel's shift is the thread's: given every time);
        ``law``: the value the FHOCP holds, whose moves move the law's steady state (False:
        the observer's model input, or a step of the prediction). Returns what moved since
        the FHOCP's last (the values in the user's names and units: the law follows them,
        :meth:`controllers.laws.base.ControlLaw.disturbance_moved`), else ``""``."""
        changed = self.shift.set(d)
        fhocp.shift_biases(self.shift.delta, changed)
        if not law:
            return ""
        moved = ""
        if self._d_law is not None and not np.array_equal(d, self._d_law):
            moved = ", ".join(
                f"{n[len('dist.'):]}={v:.4g}{(' ' + u) if u else ''}" for n, v, u in zip(
                    self.names, d * self._scale + self._offset, self._units, strict=True))
        self._d_law = np.array(d, dtype=float)
        return moved

    def ahead(self, observer: Any, fhocp: Any) -> np.ndarray | None:
        """``x̂`` predicted over the inputs' shortest dead time ``K`` (None without one): ``K``
        steps of the model with the inputs already applied (input ``j`` at step ``i``:
        ``u_{k+i−K_j}``; before the run, the input that holds the first output estimate) and
        each disturbance as the model sees it, ``d_{k+i−L}`` while known (measured, or known
        ahead), then held at ``d_k`` (each step's in the biases, then the FHOCP's again); the
        compiled kernel's GRU step when there is one, as the exported controller's. The
        FHOCP's fixed inputs (:attr:`prefix`) are set from the same past."""
        if not self.depth:
            return None
        from controllers import gru
        from controllers.equilibrium import equilibrium_for_output

        kernel = fhocp.kernel
        if self._u_past is None:
            _, u0 = equilibrium_for_output(self.model.params, observer.y_hat(), kernel)
            self._u_past = np.tile(np.clip(u0, -1.0, 1.0), (self.depth, 1))
        self.prefix.set(self._u_past)
        if not self.dead_time:
            return None
        x = np.asarray(observer.x_hat, dtype=float)
        zero = np.zeros(self.model.n)
        cols = np.arange(self.delays.size)
        one_delay = self.depth == self.dead_time   # every input as late: row i (fast path)
        for i in range(self.dead_time):
            if self.shift is not None:
                self.hold(self._seen(i), fhocp)
            v = self._u_past[i] if one_delay else self._u_past[self.depth - self.delays + i,
                                                                cols]
            x = (kernel.gru_step(x, v, zero, zero) if kernel is not None
                 else gru.step(self.model.params, x, v))
        if self.shift is not None:
            self.hold(self._d_fhocp, fhocp)   # the FHOCP's: d_k (known ahead: d_{k+K-L})
        return x

    def _seen(self, i: int) -> np.ndarray:
        """The disturbances as the model sees them ``i`` samples on, ``d_{k+i−L}``: measured
        while ``i ≤ L``, known ahead from the schedule, else held at ``d_k``."""
        if self.preview.any():
            return np.array([self._value(j, i - int(L)) for j, L in enumerate(self.lags)])
        d = self._d_past[-1].copy()
        known = i < self.lags
        d[known] = self._d_past[-1 - self.lags[known] + i, known.nonzero()[0]]
        return d

    def model_input(self, u: np.ndarray, fhocp: Any) -> np.ndarray:
        """The observer's input ``v_k`` as the model sees it: input ``j`` as applied ``K_j``
        samples ago (``u`` itself without dead time), each disturbance ``L`` samples ago
        (held in the biases for the observer's step)."""
        if self.shift is not None and (self.lags.any() or self.preview.any()):
            self.hold(self._d_past[-1 - self.lags, np.arange(self.lags.size)], fhocp)
        if not self.depth:
            return u
        if self.depth == self.dead_time:   # every input as late
            return self._u_past[0]
        rows = np.minimum(self.depth - self.delays, self.depth - 1)
        return np.where(self.delays > 0, self._u_past[rows, np.arange(self.delays.size)], u)

    def applied(self, u: np.ndarray) -> None:
        """Record the step's input (normalised): the dead time's past."""
        if self.depth:
            self._u_past = np.vstack([self._u_past[1:], u])

    def summary(self) -> dict[str, Any]:
        """``disturbances`` and ``disturbance_clipped`` (with disturbances), ``dead_time``."""
        out: dict[str, Any] = {"dead_time": self.dead_time}
        if self.prefix.depth:
            out["dead_times"] = self.delays.tolist()
        if self.shift is not None:
            out = {"disturbances": [n[len("dist."):] for n in self.names],
                   "disturbance_clipped": self.clipped, **out}
        if self.preview.any():
            out["previewed"] = [n[len("dist."):] for n, p in zip(self.names, self.preview,
                                                                 strict=True) if p]
            out["preview_held_steps"] = self.preview_held
        return out
