"""The paper's law's set-point handling for :class:`cosim_adapters.robust_mpc.
RobustMPCController` (``law="paper"``; functions of the controller, as
:mod:`cosim_adapters.tracking` for the tracking law): on a set-point change the rate limit
(``setpoint_rate``), the offset-free shift by ``d̂`` (``offset_free``), the reference
``(x̄, ū, α)`` of :meth:`controllers.certificates.Certificate.reference` (Assumption 1,
``eq:condition-recursive-feasibility``), the admissible reference governor
(:mod:`controllers.governor`) and the rejection of set-points outside the theory."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.errors import SetpointError
from cosim.errors import CosimError

__all__ = ["closest_admissible", "govern", "reject", "update_reference"]


def update_reference(ctrl: Any, y_ref: np.ndarray, y: np.ndarray, t: float) -> bool:
    """Recompute ``(x̄, ū, α)`` when the set-point changes; ``True`` when rejected."""
    target = y_ref
    if ctrl.setpoint_rate is not None and ctrl._y_model is not None:
        step = ctrl.setpoint_rate / np.abs(ctrl.model.y_scale)
        base = ctrl._y_model + (ctrl._d_hat if ctrl.offset_free and ctrl._d_hat is not None
                                else 0.0)
        target = base + np.clip(y_ref - base, -step, step)
    if ctrl.offset_free and ctrl._d_hat is not None:
        ctrl._d_hat = ctrl._d_hat + ctrl.offset_filter * (
            y - ctrl.observer.y_hat() - ctrl._d_hat)
        target = target - ctrl._d_hat
    tol = 1e-3 if ctrl.offset_free else 1e-12
    ctrl._lam = 1.0
    if ctrl._y_model is not None and np.max(np.abs(target - ctrl._y_model)) < tol:
        return False
    requested_changed = ctrl._y_ref is None or np.any(y_ref != ctrl._y_ref)
    if ctrl.governor is not None and ctrl._y_model is not None:
        return govern(ctrl, target, y_ref, requested_changed, t)
    try:
        ref = ctrl.cert.reference(target)
    except SetpointError as exc:
        if ctrl._y_model is not None:
            reject(ctrl, exc, y_ref, requested_changed, t)
            return True
        if ctrl.certification.certified:
            raise CosimError(f"controller {ctrl.name!r} at t={t:g} s: {exc}") from None
        # uncertified, a first set-point outside: the closest admissible one, else the
        # closest admissible to the model's equilibrium for the measured output
        ref = _first_admissible(ctrl, target, y)
        if ref is None:
            raise CosimError(f"controller {ctrl.name!r} at t={t:g} s: {exc}") from None
        reject(ctrl, exc, y_ref, requested_changed, t)
        target = ref.y_bar
    if requested_changed:
        ctrl.setpoint_changes += 1
    ctrl._y_ref = y_ref
    ctrl._y_model = target
    ctrl._paper_law().set_reference(ref.x_bar, ref.u_bar, ref.alpha)
    return False


#: How far inside the admissible box :func:`closest_admissible` puts a set-point
#: (normalised; Assumption 1 is a strict inequality).
INSIDE = 1e-3


def closest_admissible(cert: Any, y: np.ndarray) -> np.ndarray | None:
    """``y`` moved into the admissible box of ``cert`` (box rows ``±y_j ≤ rhs``:
    :meth:`controllers.certificates.Certificate.admissible_box`), :data:`INSIDE` within it;
    ``None`` when the box is empty for some output."""
    rhs = cert.admissible_box()
    out = np.array(y, dtype=float)
    for j in range(out.size):
        hi = min((r / row[j] for row, r in zip(cert.L, rhs, strict=True)
                  if row[j] > 0 and np.count_nonzero(row) == 1), default=np.inf)
        lo = max((r / row[j] for row, r in zip(cert.L, rhs, strict=True)
                  if row[j] < 0 and np.count_nonzero(row) == 1), default=-np.inf)
        if not lo + 2 * INSIDE <= hi:
            return None
        out[j] = min(max(out[j], lo + INSIDE), hi - INSIDE)
    return out


def _first_admissible(ctrl: Any, target: np.ndarray, y: np.ndarray) -> Any:
    """The reference of the admissible set-point closest to ``target`` (normalised), else
    to the model's equilibrium output for the measured ``y``; ``None`` when neither is."""
    from controllers.equilibrium import equilibrium_for_output

    x_eq, _ = equilibrium_for_output(ctrl.model.params, y)
    for start in (target, ctrl.model.params["U_o"] @ x_eq + ctrl.model.params["b_o"]):
        inside = closest_admissible(ctrl.cert, start)
        if inside is None:
            continue
        try:
            return ctrl.cert.reference(inside)
        except SetpointError:
            continue
    return None


def reject(ctrl: Any, exc: Exception, y_ref: np.ndarray, requested_changed: bool,
           t: float) -> None:
    """Keep the last admissible set-point: count the step, name the reason once per
    requested set-point (the summary's ``setpoint_rejections``)."""
    if requested_changed:
        ctrl.rejections.append(f"t={t:g} s: {exc}")
    ctrl._y_ref = y_ref
    ctrl.rejected += 1


def govern(ctrl: Any, target: np.ndarray, y_ref: np.ndarray, requested_changed: bool,
           t: float) -> bool:
    """Move the FHOCP set-point towards an admissible ``target`` with the governor."""
    from controllers.equilibrium import describe

    assert ctrl.governor is not None and ctrl._y_model is not None
    failed = ctrl.cert.failures(target)
    if failed:
        reject(ctrl, SetpointError(f"set-point {describe(ctrl.model, target)}: "
                                   + "; ".join(failed)), y_ref, requested_changed, t)
        return True
    if (not requested_changed and ctrl._unreachable is not None
            and np.array_equal(target, ctrl._unreachable)):
        ctrl.rejected += 1     # still the unreachable request: refused again, counted
        return True
    mpc = ctrl._paper_law()
    if requested_changed and ctrl.governor.newton(target, mpc.x_bar, mpc.u_bar) is None:
        try:  # reachable with ‖ū‖∞ ≤ 1? (the multi-start solve decides)
            ctrl.cert.reference(target)
        except SetpointError as exc:
            reject(ctrl, exc, y_ref, requested_changed, t)
            ctrl._unreachable = np.array(target, dtype=float)
            return True
    if requested_changed:
        ctrl.setpoint_changes += 1
    ctrl._y_ref = y_ref
    ctrl.governed_steps += 1
    last = mpc.records[-1].result.success if mpc.records else None
    gs = ctrl.governor.govern(ctrl.observer.x_hat, ctrl.observer.e_o, ctrl._y_model,
                              mpc.x_bar, mpc.u_bar, target, mpc.plan, last)
    if gs.lam == 0.0:
        ctrl._lam = 0.0
        ctrl.governor_holds += 1
        return False
    ctrl._lam = gs.lam
    ctrl._y_model = gs.y
    mpc.set_reference(gs.x_bar, gs.u_bar, gs.alpha)
    ctrl._candidate = gs.candidate
    return False
