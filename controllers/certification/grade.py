"""Graded guarantees of the robust MPC: certified, or uncertified with a measured tightening.

The robust MPC (:class:`controllers.mpc.RobustMPC`) runs **certified** when
every hypothesis of its law holds: the design's (``th:feasibility-stability`` for the paper's
law, the tracking law's H3–H6 of :mod:`controllers.laws.tracking.checks`) and, at each
set-point the run will request (:meth:`cosim.core.component.Component.expect_setpoints`), the
set-point's (Assumption 1 and ``eq:condition-recursive-feasibility`` for the paper's law; the
set-point inside the admissible steady outputs ``Y_s`` for the tracking law). Its constraint
tightening is then the theorem's.

Otherwise (option ``certificate = "auto"``, the default) it runs **uncertified**; with
``certificate = "require"`` (``cosim run --require-certificate``) it refuses instead
(:class:`~controllers.errors.CertificateError`, exit 2); with ``certificate = "keep"`` it keeps the
certified design whatever the set-points (the tracking law tracks one outside ``Y_s`` to the
closest admissible steady output, the paper's law refuses it; a failing design is an error).
Uncertified is the same law and cost, with the theorem's tightening (which a model that fails
the hypotheses makes vacuous: it swallows the output box) replaced by the model's measured
prediction error on held-back data (:mod:`controllers.certification.prediction_error`, written
into the model file by ``cosim train``; a model file without it is tightened by its ``w̄_y`` at
every step), zero observer gains, and, for the tracking law, the output rows tightened around
``y + d̂`` (the filtered output mismatch, the output the plant will show). No guarantee follows;
the summary says ``certified: false`` with the reason, and the run prints it once
(:attr:`Certification.notice`).

A model no mode runs is refused with :class:`NotUsable`, in the words of ``cosim certify``'s
verdict, *not usable*, whatever the option: ``ν ≥ 1`` with no finite terminal weight,
proved or measured on its linearisation
(:meth:`controllers.certification.certificates.Certificate.unusable`), or, for the tracking
law, a measured tightening that leaves no admissible output in the box, or none that a steady
state of the model reaches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.errors import CertificateError, ControllersError, DesignError

__all__ = ["Certification", "NotUsable", "check_setpoints", "go_uncertified", "margin_text",
           "uncertified_certificate"]



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


def check_setpoints(ctrl: Any, setpoints: list[dict[str, float]]) -> str:
    """The first of ``setpoints`` (physical, by output name) outside the certified design, as
    a reason (empty when every one is inside). Set-points naming another output's set are
    skipped where an output is missing."""
    names = list(ctrl.problem.output_names)
    for sp in setpoints:
        if not all(n in sp for n in names):
            continue
        reason = ctrl.law.setpoint_reason(
            ctrl.model.normalize_y(np.array([sp[n] for n in names], dtype=float)))
        if reason:
            return reason
    return ""


#: The uncertified tightening of a row is at most this share of the box's width along it
#: (``rem:uncertified-cap``, docs: design/soft-constraints.md): a model whose measured
#: prediction error over the horizon is wider (the zoo's Wood–Berry column: 1.9 mol% of a
#: 2.4 mol% box, most of it its feed flow moving while the prediction holds it) left no
#: admissible output and was refused; capped, it runs, and the softened FHOCP answers where
#: a prediction leaves the capped rows. Measured on its scenario: a quarter of the width
#: kept xB = 0.5 mol% out of the admissible steady outputs (a static offset, IAE of xB 0.17×
#: the PI's), a tenth admits it (0.09×), both with no violation (the PI: 115 samples).
MARGIN_CAP = 0.1


def measured_margins(ctrl: Any, cert: Any) -> tuple[np.ndarray, str]:
    """The uncertified tightening of ``cert``'s rows over its horizon, and where it came from:
    the model file's ``prediction_error``, else its ``w̄_y`` at every step; what the horizon
    adds to the first stage's capped at :data:`MARGIN_CAP` of the box's width along the row
    (:func:`row_widths`): a model whose error one step ahead fills the box stays refused."""
    from controllers.certification.prediction_error import margins
    from controllers.dead_time import input_delay

    profile = ctrl.model.prediction_error
    if profile is not None:
        found = margins(profile, cert.L, cert.N, input_delay(ctrl.problem)), "prediction_error"
    else:
        w = float(ctrl.model.w_y_bar if ctrl.model.w_y_bar is not None else cert.w_y_bar)
        found = np.full(cert.a.shape, w) * np.abs(cert.L).sum(axis=1), "w_y_bar"
    cap = np.maximum(MARGIN_CAP * row_widths(cert.L, cert.h), found[0][min(1, cert.N)])
    return np.minimum(found[0], cap), found[1]


def row_widths(L: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The width of the output set ``{y : L y ≤ h}`` along each row (``h_j + h_k`` for a row
    ``k`` opposite to ``j``, a box's; ``inf`` for a row without one)."""
    L, h = np.atleast_2d(np.asarray(L, dtype=float)), np.asarray(h, dtype=float)
    out = np.full(h.shape, np.inf)
    for j in range(L.shape[0]):
        for k in range(L.shape[0]):
            if np.allclose(L[k], -L[j], rtol=0, atol=1e-15):
                out[j] = h[j] + h[k]
    return out


def margin_text(model: Any, cert: Any) -> str:
    """The measured tightening at the horizon's end, per output, in its units."""
    m = cert.b[-1]
    problem = model.problem
    parts = []
    for j, name in enumerate(problem.output_names):
        rows = [k for k in range(cert.L.shape[0]) if cert.L[k, j] != 0]
        value = max(m[k] for k in rows) * abs(float(model.y_scale[j]))
        parts.append(f"{name} {value:.4g} {problem.output_units[j]}".rstrip())
    return ", ".join(parts)


#: How a refusal of a model no mode runs begins, after the controller's name (``cosim certify``
#: reads the reason after it: its verdict and ``cosim run``'s error are the same words).
NOT_USABLE = "the model is not usable: "


class NotUsable(ControllersError, ValueError):
    """The robust MPC refuses the model, certified or not: ``controller 'mpc': the model is not
    usable: <why; fix: ...>`` (:attr:`why`)."""

    def __init__(self, component: str, why: str) -> None:
        super().__init__(f"controller {component!r}: {NOT_USABLE}{why}")
        self.component, self.why = component, why

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        """Pickled as its arguments: a refusal raised in a worker process (``cosim tune``'s
        closed loops, a campaign's) reaches the parent as the same refusal."""
        return (NotUsable, (self.component, self.why))


def go_uncertified(ctrl: Any, reason: str) -> None:
    """Switch ``ctrl`` to the uncertified design (module docstring): the same law
    (:meth:`controllers.laws.base.ControlLaw.uncertified`) on the certificate tightened by the
    measured prediction error, zero observer gains; or refuse when it requires a
    certificate, or when no mode runs the model (in the words of ``cosim certify``'s
    verdict)."""
    from controllers.observer import GRUObserver

    cert = ctrl.cert
    unusable = cert.unusable()
    if unusable:
        raise NotUsable(ctrl.name, unusable)
    if ctrl.certificate_mode != "auto":
        raise CertificateError(f"controller {ctrl.name!r}: the model is not certified for this "
                               f"run ({reason}); with the option certificate=\"auto\" (the "
                               "default; not --require-certificate) it runs uncertified")
    cert_u = uncertified_certificate(cert, measured_margins(ctrl, cert)[0])
    ctrl.law = ctrl.law.uncertified(cert_u, reason)
    ctrl.observer = GRUObserver.from_certificate(ctrl.cert)
    ctrl.certification = Certification(False, reason, "measured")


def uncertified_certificate(cert: Any, margins: np.ndarray) -> Any:
    """The design of the uncertified mode: ``cert``'s model, weights and terminal weight, with
    the theorem's tightening ``a_i ê_o + b_i + w_L`` replaced by measured ``margins``
    (``(N + 1, q)``, :func:`controllers.certification.prediction_error.margins`) and zero
    observer gains (the observer runs the model). Every row is tightened by ``margins[i]`` at
    step ``i``: ``a = 0``, ``b = margins``, ``w_L = 0``, ``ê_o = 0``; ``α`` (``eq:def-alpha``)
    and Assumption 1 use the same margins; no guarantee follows from them
    (``tightening = "measured"``). The ``i = 0`` rows, on the estimate ``x̂`` alone (no input
    changes them; the theorem's recursive feasibility, which keeps them satisfied, is what this
    design lacks), are not enforced: their margin is ``−∞``.

    The terminal weight is the smaller of the theorem's ``s`` (``eq:definition_s``) and the one
    measured on the model's linearisation at its steady states
    (:mod:`controllers.certification.measured_terminal`, ``ŝ``; ``rem:measured-terminal`` in
    docs: design/soft-constraints.md): both bound the cost to go from the horizon's end, the
    theorem's for every state of the box with the worst-case contraction ``ρ_s``, the measured
    one near the steady states the controller steers to. With ``ρ_s`` near 1 the theorem's is
    the larger by far (the zoo's air heater: 266,163 against 4,080), and a terminal weight that
    large holds the artificial steady state to where the horizon's end can reach: it crawls
    after a set-point step the plant can only follow slowly."""
    from dataclasses import replace

    margins = np.array(margins, dtype=float)
    if margins.shape != cert.a.shape:
        raise DesignError(f"margins have shape {margins.shape}, expected {cert.a.shape}")
    margins[0] = -np.inf
    zero = np.zeros_like(cert.L_z)
    s, rho, measured = cert.s, cert.rho_s, cert.measured
    if measured is None:
        from controllers.certification.measured_terminal import measured_terminal_weight

        measured = measured_terminal_weight(cert.params, cert.Q)
    if math.isfinite(measured.s) and not measured.s >= s:
        # the terminal weight measured on the linearisation (ν ≥ 1: the only one), and the
        # contraction eq:definition_s would need for it (controllers.certification.
        # measured_terminal)
        from controllers.certification.measured_terminal import equivalent_contraction

        s = measured.s
        rho = equivalent_contraction(cert.n, cert.Q, s)
    return replace(cert, L_z=zero, L_r=zero.copy(), nu_o=cert.nu, rho_s=rho, rho_o=rho,
                   kappa=0.0, L_max=0.0, w_bar=0.0, w_L=np.zeros_like(cert.w_L),
                   a=np.zeros_like(cert.a), b=margins, e_o0=0.0, e_inf=0.0, gain_scale=0.0,
                   s=s, tightening="measured", measured=measured)
