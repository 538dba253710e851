"""The paper's law (``law="paper"``) of the robust MPC: :class:`PaperLaw`, and :func:`build`.

``u_k = k^MPC(x̂_k, ê_o,k)`` (``eq:mpc``, :class:`controllers.laws.paper.mpc.PaperMPC`: the FHOCP
``eq:optimization`` with the shifted-candidate fallback) for the reference ``(x̄, ū, α)`` of
:meth:`controllers.certification.certificates.Certificate.reference` (Assumption 1, ``eq:condition-
recursive-feasibility``), and its set-point handling: on a set-point change the rate limit
(``setpoint_rate``), the offset-free shift by ``d̂`` (``offset_free``), the admissible
reference governor (:mod:`controllers.laws.paper.governor`) and the rejection of set-points
outside the theory. It implements :class:`controllers.laws.base.ControlLaw`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.errors import SetpointError
from controllers.laws.base import (
    LawContext,
    LawStep,
    Setting,
    refuse_shared,
    refuse_weight,
    setpoint_text,
)
from controllers.laws.paper.reference import FixedSetpoint

__all__ = ["PaperLaw", "SetpointHandling", "build", "closest_admissible", "settings_of"]


@dataclass(frozen=True)
class SetpointHandling:
    """How the paper's law meets a set-point change (the options of these names).

    Attributes
    ----------
    governor : bool
        The admissible reference governor after set-point changes.
    offset_free : bool
        Shift the set-point by ``d̂`` (outside the theorem).
    offset_filter : float
        ``β`` of ``d̂ ← d̂ + β (y − ŷ − d̂)``.
    setpoint_rate : float or None
        Largest move of the FHOCP's set-point per sample, in the outputs' units.
    """

    governor: bool
    offset_free: bool
    offset_filter: float
    setpoint_rate: float | None


def build(ctx: LawContext) -> tuple[PaperLaw, list[str]]:
    """The paper's law of the design ``ctx`` on its certificate (the observer gains of
    ``ctx.cert``) and the certificate's hypotheses that fail (:mod:`controllers.laws`)."""
    o = ctx.options
    rate = o.option("setpoint_rate")
    handling = SetpointHandling(bool(o.option("governor")), bool(o.option("offset_free")),
                                float(o.offset_filter), None if rate is None else float(rate))
    law = PaperLaw(ctx.model, ctx.cert, ctx.fhocp_options, handling, name=ctx.name)
    return law, ctx.cert.failures()


def settings_of(beta: float | None, R: np.ndarray, du: np.ndarray | None,
                rate: float | None, inputs: list[str]) -> list[Setting]:
    """The paper's law's settings (the C step's tunable parameters, ``law.c``'s
    ``LAW_P_*`` order), with these values: the disturbance filter's gain (``beta``: with
    ``offset_free``), the diagonal of ``R``, the input-rate weights (``du``: with the term),
    the set-point rate (``rate``: designed with one)."""
    inf = float("inf")
    out = []
    if beta is not None:
        out.append(("offset_filter", 0.0, 1.0, "gain of the output-disturbance estimate "
                    "d_hat, in (0, 1] (option offset_filter)", float(beta)))
    out += [(f"R.{name}", 0.0, inf, f"input weight R of {name} (diagonal entry; R stays "
             "positive definite; option R)", float(R[j, j])) for j, name in enumerate(inputs)]
    if du is not None:
        out += [(f"du_weight.{name}", 0.0, inf, f"input-rate weight S of {name}, >= 0 "
                 "(option du_weight)", float(du[j])) for j, name in enumerate(inputs)]
    if rate is not None:
        out.append(("setpoint_rate", 0.0, inf, "largest move of the set-point per sample, "
                    "> 0, in each output's units (option setpoint_rate)", float(rate)))
    return out


class PaperLaw:
    """The paper's law with its set-point handling (module docstring).

    Parameters
    ----------
    model : GRUModel
    cert : Certificate
        Its certificate (the tightening, ``(x̄, ū, α)`` of each set-point).
    fhocp_options : mapping
        :class:`controllers.ocp.fhocp.FHOCP` keyword arguments (solver, kernel, ``du_weight``).
    handling : SetpointHandling
        The governor, the offset-free shift, its filter and the set-point rate.
    name : str
        The component's name (in error messages).
    certified : bool
        Whether the certificate covers the run: an uncertified law takes the closest
        admissible set-point where the first one is outside, instead of refusing it.
    """

    name = "paper"
    #: operator limits on its outputs and outputs out of its cost (controllers.mpc_operating)
    output_limits = False

    def __init__(self, model: Any, cert: Any, fhocp_options: dict[str, Any],
                 handling: SetpointHandling, *, name: str, certified: bool = True) -> None:
        from controllers.laws.paper.governor import ReferenceGovernor
        from controllers.laws.paper.mpc import PaperMPC
        from controllers.ocp.fhocp import FHOCP

        self.model, self.cert, self.fhocp_options = model, cert, dict(fhocp_options)
        self.fhocp = FHOCP.from_certificate(cert, reference=FixedSetpoint(), **self.fhocp_options)
        self.mpc = PaperMPC(self.fhocp)
        self.handling = handling
        self.governor = ReferenceGovernor(cert, self.fhocp) if handling.governor else None
        self.certified, self.component = certified, name
        self.reset()

    # -- ControlLaw ------------------------------------------------------------------------
    @property
    def records(self) -> list[Any]:
        return self.mpc.records

    @property
    def alpha(self) -> float:
        return self.mpc.alpha

    @property
    def steady_state(self) -> np.ndarray | None:
        return self.mpc.x_bar

    def reset(self) -> None:
        self.mpc.reset()
        if self.governor is not None:
            self.governor.reset()
        self.y_ref: np.ndarray | None = None      # requested set-point (normalised)
        self.y_model: np.ndarray | None = None    # set-point given to the FHOCP
        self.d_hat: np.ndarray | None = None
        self.lam = 1.0
        self.candidate: np.ndarray | None = None
        self.unreachable: np.ndarray | None = None   # the last target refused as unreachable
        self.rejected = 0
        self.rejections: list[str] = []
        self.setpoint_changes = 0
        self.governed_steps = 0     # steps with the FHOCP set-point short of the requested
        self.governor_holds = 0     # of which the governor could not move it at all
        self.moved_refusal = ""     # why the disturbances' last move left no reference
        self.disturbance_refusals = 0

    def step(self, observer: Any, y: np.ndarray, y_ref: np.ndarray, t: float,
             x_start: np.ndarray | None = None) -> LawStep:
        x0 = observer.x_hat if x_start is None else x_start
        if self.d_hat is None:
            self.d_hat = np.zeros_like(y)
        self.candidate = None
        if self.moved_refusal:
            self.rejections.append(f"t={t:g} s: {self.moved_refusal}")
            self.moved_refusal = ""
        rejected = self._update_reference(observer, y_ref, y, t, x0)
        rec = self.mpc.make_step(x0, observer.e_o, candidate=self.candidate)
        y_model = self.model.denormalize_y(self.y_model)
        names = self.model.problem.output_names
        return LawStep(rec, rejected, {f"y_model_{n}": float(v)
                                       for n, v in zip(names, y_model, strict=True)}, self.lam)

    def disturbance_moved(self, measured: str = "") -> None:
        """The reference of the FHOCP's set-point again under the disturbances now held: the
        equilibrium with the same output (its ``ū`` the nonlinear static feedforward), the
        plan moved by the same input change; the governor forgets the equilibrium it kept
        for the request, and a request refused as unreachable is tried again. Where the new
        disturbances leave the set-point unreachable, the closest reachable output takes its
        place (the last reference kept when that one fails the theory's checks), counted
        (``disturbance_refusals``) and named at the next step (``setpoint_rejections``);
        the governor moves back towards the request when the disturbances allow it."""
        from controllers.equilibrium import describe, equilibrium_for_output

        self.unreachable = None
        if self.governor is not None:
            self.governor.forget_target()
        mpc, kernel = self.mpc, self.fhocp.kernel
        if self.y_model is None or mpc.u_bar is None:
            return
        try:
            ref = self.cert.reference(self.y_model, kernel=kernel)
        except SetpointError:
            x_eq, _ = equilibrium_for_output(self.model.params, self.y_model, kernel)
            y_eq = (kernel.output(x_eq) if kernel is not None   # the exported controller's
                    else self.model.params["U_o"] @ x_eq + self.model.params["b_o"])
            try:
                ref = self.cert.reference(y_eq, kernel=kernel)
                instead = f"the closest reachable output, {describe(self.model, y_eq)}, instead"
            except SetpointError:
                ref, instead = None, "the last reference kept"
            self.disturbance_refusals += 1
            self.moved_refusal = (f"set-point {describe(self.model, self.y_model)} is not "
                                  f"reachable at {measured or 'the measured disturbances'}: "
                                  f"{instead}")
            if ref is None:
                return
            self.y_model = ref.y_bar
        if mpc.plan is not None:
            mpc.plan = np.clip(mpc.plan + (ref.u_bar - mpc.u_bar), -1.0, 1.0)
        mpc.set_reference(ref.x_bar, ref.u_bar, ref.alpha)

    def restart(self) -> None:
        """Nothing: the paper's law's next solve starts from its shifted plan, as after a
        set-point change without the governor."""

    def setpoint_reason(self, y: np.ndarray) -> str:
        failed = self.cert.failures(y)
        return f"{setpoint_text(self.model, y)}: {failed[0]}" if failed else ""

    def uncertified(self, cert: Any, reason: str) -> PaperLaw:
        return PaperLaw(self.model, cert, self.fhocp_options, self.handling,
                        name=self.component, certified=False)

    def settings(self) -> list[Setting]:
        fh, h = self.fhocp, self.handling
        return settings_of(h.offset_filter if h.offset_free else None, fh.R,
                           fh.du_weight if fh.has_du else None, h.setpoint_rate,
                           list(self.model.problem.input_names))

    def refuse(self, name: str, value: float) -> str:
        shared = refuse_shared(name, value, self.fhocp.R, list(self.model.problem.input_names))
        if shared is not None:
            return shared
        if name == "setpoint_rate":
            return "" if np.isfinite(value) and value > 0.0 else "must be a finite rate > 0"
        return refuse_weight(value, positive=False)

    def set(self, name: str, value: float) -> str:
        from dataclasses import replace

        family, _, signal = name.partition(".")
        if family == "offset_filter":
            self.handling = replace(self.handling, offset_filter=float(value))
            return "the output-disturbance estimate's gain (outside the theorem)"
        if family == "setpoint_rate":
            self.handling = replace(self.handling, setpoint_rate=float(value))
            return "the set-point's rate limit (outside the theorem)"
        self.fhocp.set_weight("R" if family == "R" else "du",
                              self.model.problem.input_names.index(signal), float(value))
        return "the FHOCP's input cost (th:feasibility-stability holds for any R > 0)"

    def applied(self, u: np.ndarray) -> None:
        self.mpc.u_prev = np.array(u, dtype=float)

    def control(self, controlled: np.ndarray) -> str:
        from controllers.errors import OptionError

        if not np.all(controlled):
            raise OptionError("the paper's law regulates to the equilibrium of every output "
                              "(eq:mpc): an output cannot leave its cost; use law=tracking")
        return "every output controlled"

    def summary(self) -> dict[str, Any]:
        h = self.handling
        return {"offset_free": h.offset_free, "setpoint_rate": h.setpoint_rate,
                "governor": self.governor is not None,
                "governor_steps": self.governed_steps, "governor_holds": self.governor_holds,
                "setpoint_changes": self.setpoint_changes,
                "setpoint_rejected_steps": self.rejected,
                "disturbance_refusals": self.disturbance_refusals,
                "setpoint_rejections": self.rejections[:20]}

    # -- the set-point handling -------------------------------------------------------------
    def _update_reference(self, observer: Any, y_ref: np.ndarray, y: np.ndarray,
                          t: float, x0: np.ndarray) -> bool:
        """Recompute ``(x̄, ū, α)`` when the set-point changes (the governor's candidates
        from ``x0``, the state the FHOCP starts from); ``True`` when rejected."""
        h = self.handling
        target = y_ref
        if h.setpoint_rate is not None and self.y_model is not None:
            step = h.setpoint_rate / np.abs(self.model.y_scale)
            base = self.y_model + (self.d_hat if h.offset_free else 0.0)
            target = base + np.clip(y_ref - base, -step, step)
        if h.offset_free:
            self.d_hat = self.d_hat + h.offset_filter * (y - observer.y_hat() - self.d_hat)
            target = target - self.d_hat
        tol = 1e-3 if h.offset_free else 1e-12
        self.lam = 1.0
        if self.y_model is not None and np.max(np.abs(target - self.y_model)) < tol:
            return False
        requested_changed = self.y_ref is None or np.any(y_ref != self.y_ref)
        if self.governor is not None and self.y_model is not None:
            return self._govern(observer, target, y_ref, requested_changed, t, x0)
        try:
            ref = self.cert.reference(target, kernel=self.fhocp.kernel)
        except SetpointError as exc:
            if self.y_model is not None:
                self._reject(exc, y_ref, requested_changed, t)
                return True
            if self.certified:
                raise SetpointError(f"controller {self.component!r} at t={t:g} s: {exc}") \
                    from None
            # uncertified, a first set-point outside: the closest admissible one, else the
            # closest admissible to the model's equilibrium for the measured output
            ref = self._first_admissible(target, y)
            if ref is None:
                raise SetpointError(f"controller {self.component!r} at t={t:g} s: {exc}") \
                    from None
            self._reject(exc, y_ref, requested_changed, t)
            target = ref.y_bar
        if requested_changed:
            self.setpoint_changes += 1
        self.y_ref = y_ref
        self.y_model = target
        self.mpc.set_reference(ref.x_bar, ref.u_bar, ref.alpha)
        return False

    def _first_admissible(self, target: np.ndarray, y: np.ndarray) -> Any:
        """The reference of the admissible set-point closest to ``target`` (normalised), else
        to the model's equilibrium output for the measured ``y``; ``None`` when neither is."""
        from controllers.equilibrium import equilibrium_for_output

        kernel = self.fhocp.kernel
        x_eq, _ = equilibrium_for_output(self.model.params, y, kernel)
        y_eq = (kernel.output(x_eq) if kernel is not None   # the exported controller's sum
                else self.model.params["U_o"] @ x_eq + self.model.params["b_o"])
        for start in (target, y_eq):
            inside = closest_admissible(self.cert, start)
            if inside is None:
                continue
            try:
                return self.cert.reference(inside, kernel=kernel)
            except SetpointError:
                continue
        return None

    def _reject(self, exc: Exception, y_ref: np.ndarray, requested_changed: bool,
                t: float) -> None:
        """Keep the last admissible set-point: count the step, name the reason once per
        requested set-point (the summary's ``setpoint_rejections``)."""
        if requested_changed:
            self.rejections.append(f"t={t:g} s: {exc}")
        self.y_ref = y_ref
        self.rejected += 1

    def _govern(self, observer: Any, target: np.ndarray, y_ref: np.ndarray,
                requested_changed: bool, t: float, x0: np.ndarray) -> bool:
        """Move the FHOCP set-point towards an admissible ``target`` with the governor (its
        candidates rolled out from ``x0``)."""
        from controllers.equilibrium import describe

        assert self.governor is not None and self.y_model is not None
        failed = self.cert.failures(target)
        if failed:
            self._reject(SetpointError(f"set-point {describe(self.model, target)}: "
                                       + "; ".join(failed)), y_ref, requested_changed, t)
            return True
        if (not requested_changed and self.unreachable is not None
                and np.array_equal(target, self.unreachable)):
            self.rejected += 1     # still the unreachable request: refused again, counted
            return True
        mpc = self.mpc
        if requested_changed and self.governor.newton(target, mpc.x_bar, mpc.u_bar) is None:
            try:  # reachable with ‖ū‖∞ ≤ 1? (the multi-start solve decides)
                self.cert.reference(target, kernel=self.fhocp.kernel)
            except SetpointError as exc:
                self._reject(exc, y_ref, requested_changed, t)
                self.unreachable = np.array(target, dtype=float)
                return True
        if requested_changed:
            self.setpoint_changes += 1
        self.y_ref = y_ref
        self.governed_steps += 1
        last = mpc.records[-1].result.success if mpc.records else None
        gs = self.governor.govern(x0, observer.e_o, self.y_model,
                                  mpc.x_bar, mpc.u_bar, target, mpc.plan, last)
        if gs.lam == 0.0:
            self.lam = 0.0
            self.governor_holds += 1
            return False
        self.lam = gs.lam
        self.y_model = gs.y
        mpc.set_reference(gs.x_bar, gs.u_bar, gs.alpha)
        self.candidate = gs.candidate
        return False


#: How far inside the admissible box :func:`closest_admissible` puts a set-point
#: (normalised; Assumption 1 is a strict inequality).
INSIDE = 1e-3


def closest_admissible(cert: Any, y: np.ndarray) -> np.ndarray | None:
    """``y`` moved into the admissible bounds of ``cert`` (:meth:`controllers.certification.
    certificates.Certificate.admissible_bounds`), :data:`INSIDE` within them; ``None`` when
    a range is empty for some output."""
    lo, hi = cert.admissible_bounds()
    out = np.array(y, dtype=float)
    for j in range(out.size):
        if not lo[j] + 2 * INSIDE <= hi[j]:
            return None
        out[j] = min(max(out[j], lo[j] + INSIDE), hi[j] - INSIDE)
    return out
