"""Graded guarantees of the ``robust-mpc`` component: certified, or uncertified with a measured
tightening.

The robust MPC (:class:`cosim_adapters.robust_mpc.RobustMPCController`) runs **certified**
when every hypothesis of its law holds: the design's (``th:feasibility-stability`` for the
paper's law, the tracking law's H3–H6 of :mod:`controllers.tracking_checks`) and, at each
set-point the run will request (:meth:`cosim.component.Component.expect_setpoints`), the
set-point's (Assumption 1 and ``eq:condition-recursive-feasibility`` for the paper's law; the
set-point inside the admissible steady outputs ``Y_s`` for the tracking law). Its constraint
tightening is then the theorem's.

Otherwise (option ``certificate = "auto"``, the default) it runs **uncertified**; with
``certificate = "require"`` (``cosim run --require-certificate``) it refuses instead
(:class:`cosim.errors.CosimError`, exit 2); with ``certificate = "keep"`` it keeps the
certified design whatever the set-points (the tracking law tracks one outside ``Y_s`` to the
closest admissible steady output, the paper's law refuses it; a failing design is an error).
Uncertified is the same law and cost, with the theorem's
tightening (which a model that fails the hypotheses makes vacuous: it swallows the output
box) replaced by the model's measured prediction error on held-back data
(:mod:`controllers.prediction_error`, written into the model file by ``cosim train``; a model
file without it is tightened by its ``w̄_y`` at every step), zero observer gains, and, for the
tracking law, the output rows tightened around ``y + d̂`` (the filtered output mismatch, the
output the plant will show). No guarantee follows; the summary says ``certified: false`` with
the reason, and the run prints it once (:attr:`Certification.notice`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.errors import CosimError

__all__ = ["CERTIFICATE_MODES", "Certification", "check_setpoints", "go_uncertified"]

#: The ``certificate`` option of the robust MPC (module docstring).
CERTIFICATE_MODES = ("auto", "require", "keep")


@dataclass
class Certification:
    """The controller's grade: ``certified``, and why not (``reason``, one line)."""

    certified: bool = True
    reason: str = ""
    tightening: str = "theorem"

    @property
    def notice(self) -> str | None:
        """The one line a run prints at its start (``None`` when certified)."""
        if self.certified:
            return None
        return (f"uncertified: {self.reason}; running with the constraints tightened by the "
                "model's measured prediction error on held-back data (no guarantee)")

    def summary(self) -> dict[str, Any]:
        """``certified``, ``certificate_reason``, ``tightening`` for ``summary.json``."""
        return {"certified": self.certified, "certificate_reason": self.reason or None,
                "tightening": self.tightening}


def _setpoint_text(ctrl: Any, y: np.ndarray) -> str:
    return ", ".join(f"{n}={v:.4g} {u}".rstrip() for n, v, u in zip(
        ctrl.problem.output_names, ctrl.model.denormalize_y(y), ctrl.problem.output_units,
        strict=True))


def _ys_text(ctrl: Any) -> str:
    """The admissible steady outputs ``Y_s`` of a box problem, per output, in its units."""
    fh = ctrl.fhocp
    parts = []
    for j, name in enumerate(ctrl.problem.output_names):
        hi = lo = None
        for row, rhs in zip(fh.L, fh.ys_bounds, strict=True):
            if row[j] > 0 and np.count_nonzero(row) == 1:
                hi = rhs / row[j]
            elif row[j] < 0 and np.count_nonzero(row) == 1:
                lo = rhs / row[j]
        if lo is None or hi is None:
            continue
        a, b = sorted(ctrl.model.denormalize_y(np.full(ctrl.model.p, v))[j] for v in (lo, hi))
        unit = ctrl.problem.output_units[j]
        parts.append(f"{name} in [{a:.4g}, {b:.4g}] {unit}".rstrip() if a <= b
                     else f"{name}: none")
    return "; ".join(parts)


def check_setpoints(ctrl: Any, setpoints: list[dict[str, float]]) -> str:
    """The first of ``setpoints`` (physical, by output name) outside the certified design, as
    a reason (empty when every one is inside). Set-points naming another output's set are
    skipped where an output is missing."""
    names = list(ctrl.problem.output_names)
    for sp in setpoints:
        if not all(n in sp for n in names):
            continue
        y = ctrl.model.normalize_y(np.array([sp[n] for n in names], dtype=float))
        if ctrl.tracker is not None:
            fh = ctrl.fhocp
            if np.any(fh.L @ y > fh.ys_bounds + 1e-12):
                return (f"set-point {_setpoint_text(ctrl, y)} is outside the certified steady "
                        f"outputs ({_ys_text(ctrl) or 'none'})")
        else:
            failed = ctrl.cert.failures(y)
            if failed:
                return f"set-point {_setpoint_text(ctrl, y)}: {failed[0]}"
    return ""


def measured_margins(ctrl: Any, cert: Any) -> tuple[np.ndarray, str]:
    """The uncertified tightening of ``cert``'s rows over its horizon, and where it came from:
    the model file's ``prediction_error``, else its ``w̄_y`` at every step."""
    from controllers.prediction_error import margins

    profile = ctrl.model.prediction_error
    if profile is not None:
        return margins(profile, cert.L, cert.N), "prediction_error"
    w = float(ctrl.model.w_y_bar if ctrl.model.w_y_bar is not None else cert.w_y_bar)
    return np.full(cert.a.shape, w) * np.abs(cert.L).sum(axis=1), "w_y_bar"


def _margin_text(ctrl: Any, cert: Any) -> str:
    """The measured tightening at the horizon's end, per output, in its units."""
    m = cert.b[-1]
    parts = []
    for j, name in enumerate(ctrl.problem.output_names):
        rows = [k for k in range(cert.L.shape[0]) if cert.L[k, j] != 0]
        value = max(m[k] for k in rows) * abs(float(ctrl.model.y_scale[j]))
        parts.append(f"{name} {value:.4g} {ctrl.problem.output_units[j]}".rstrip())
    return ", ".join(parts)


def go_uncertified(ctrl: Any, reason: str) -> None:
    """Switch ``ctrl`` to the uncertified design (module docstring), or refuse when it
    requires a certificate."""
    from controllers.certificates import uncertified_certificate
    from controllers.fhocp import FHOCP
    from controllers.governor import ReferenceGovernor
    from controllers.observer import GRUObserver
    from controllers.robust_mpc import RobustMPC

    if ctrl.certificate_mode != "auto":
        raise CosimError(f"controller {ctrl.name!r}: the model is not certified for this run "
                         f"({reason}); with the option certificate=\"auto\" (the default; not "
                         "--require-certificate) it runs uncertified")
    design = ctrl.design
    base = ctrl.cert
    cert_u = uncertified_certificate(base, measured_margins(ctrl, base)[0])
    if ctrl.tracker is not None:
        from cosim_adapters.tracking import tracking_design

        cert_u, tracker, disturbance, _ = tracking_design(
            ctrl.model, ctrl.problem, cert_u, design["kwargs"], design["offset_weight"],
            design["alpha_c"], ctrl.disturbance.beta, design["fhocp_options"],
            design["control_horizon"], gains_certified=False, cert=cert_u)
        if not tracker.hypotheses["Ys_nonempty"]:
            given = design["alpha_c"]
            raise CosimError(
                f"controller {ctrl.name!r}: {reason}, and even the model's measured "
                f"prediction error ({_margin_text(ctrl, cert_u)}) leaves no admissible output "
                "in the box" + (f" with alpha_c = {given:g}: a smaller alpha_c" if given
                                is not None else ": the model is too far from the plant to "
                                "control it; train it longer or on more data"))
        ctrl.tracker, ctrl.disturbance, ctrl.fhocp = tracker, disturbance, tracker.fhocp
    else:
        ctrl.fhocp = FHOCP.from_certificate(cert_u, **design["fhocp_options"])
        ctrl.mpc = RobustMPC(ctrl.fhocp)
        if ctrl.governor is not None:
            ctrl.governor = ReferenceGovernor(cert_u, ctrl.fhocp)
    ctrl.cert = cert_u
    ctrl.observer = GRUObserver.from_certificate(cert_u)
    ctrl.certification = Certification(False, reason, "measured")
