"""The paper's certificate of one model and design: every quantity of the theory, checked.

Every quantity of the theory of Schimperna & Magni is computed here from the GRU weights and
the design choices (horizon ``N``, weights ``Q``/``R``, observer gains, ``ê_o,0``, ``w̄_y``),
in the model's NORMALISED units, under the paper's names:

- ``sigma_z, sigma_r, phi_h``: gate bounds σ̄_z, σ̄_r, φ̄_h (``th:stability-bonassi``);
- ``nu``: δISS index ν, δISS when ν < 1 (``eq:condition-deltaiss-gru``);
- ``rho_s, c_s``: contraction and constraint gain of V_s (``lem:Vs``);
- ``L_z, L_r``: observer gains (``eq:observer``);
- ``nu_o, rho_o, c_o, kappa, L_max``: observer index, contraction, constraint gain, gain of
  w_y and of the estimation error (``lem:Vo``);
- ``w_y_bar, w_bar``: bound of w_y and w̄ = κ w̄_y (``eq:w-bar``);
- ``w_L``: w_L(j) = Σ_k |L_jk| w̄_y (``eq:optimization``);
- ``a, b``: tightening coefficients, i = 0..N (``eq:constraint_tightening_parameters``);
- ``e_o0, e_inf``: ê_o,0 and ē_∞ = w̄ / (1 − ρ_o) (``eq:eo-evolution``);
- ``s``: terminal weight n λ_max(Q) / (1 − ρ_s²) (``eq:definition_s``);
- ``alpha``: terminal set radius for a set-point (``eq:def-alpha``); Assumption 1
  (``ass:setpoint``) and ``eq:condition-recursive-feasibility`` per set-point.

Typos of the paper handled here: the terminal cost is ``s ‖x_N − x̄‖∞²`` (the paper prints a
``+``), and the proof of ``th:feasibility-stability`` writes ``(1 + ρ_s²)`` where
``eq:definition_s`` (used here) needs ``(1 − ρ_s²)``.

Pure bounds live in :mod:`controllers.certification.bounds`, the observer-gain design in
:mod:`controllers.certification.gain_design`, the admissible outputs as intervals in
:mod:`controllers.certification.output_ranges`, ``w̄_y`` measured on data in
:mod:`controllers.certification.prediction_error`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.certification.bounds import (
    L_max,
    c_s,
    check_gates,
    contraction,
    e_inf,
    e_o_sequence,
    gate_bounds,
    kappa,
    nu,
    nu_o,
    terminal_weight,
    tightening_parameters,
    w_L,
)
from controllers.certification.design import (
    MAX_HORIZON,
    horizon,
    observer_gains,
    scalars,
    weight,
)
from controllers.certification.output_ranges import box_bounds
from controllers.errors import DesignError, SetpointError
from controllers.problem import ControlProblem, constraint_names, output_constraints

if TYPE_CHECKING:
    from controllers.certification.measured_terminal import MeasuredTerminal

__all__ = ["JSON_KEYS", "MAX_HORIZON", "NU_FIX", "Certificate", "Reference",
           "compute_certificate"]

#: What would make a model with ``ν ≥ 1`` usable (``cosim certify``'s fix, ``cosim run``'s).
NU_FIX = "train the model with the nu constraint (cosim train keeps nu <= 0.98)"

JSON_KEYS = ("sigma_z", "sigma_r", "phi_h", "nu", "rho_s", "c_s", "L_z", "L_r", "nu_o",
             "rho_o", "c_o", "kappa", "L_max", "w_y_bar", "w_bar", "w_L", "a", "b", "e_o0",
             "e_inf", "s", "s_measured", "alpha", "assumption_1", "recursive_feasibility")


# --------------------------------------------------------------------------------------
# The certificate
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Reference:
    """Set-point data of the FHOCP (normalised): ``ȳ``, equilibrium ``(x̄, ū)`` and ``α``
    (``eq:def-alpha``)."""

    y_bar: np.ndarray
    x_bar: np.ndarray
    u_bar: np.ndarray
    alpha: float


@dataclass
class Certificate:
    """Every quantity of the theory for one model and one design, paper names as attributes.

    Set-point dependent quantities (``alpha``, Assumption 1, ``eq:condition-recursive-
    feasibility``) are methods taking the set-point in normalised units. All arrays indexed
    by constraint ``j`` have ``q`` entries (rows of ``L``); ``a`` and ``b`` are ``(N+1, q)``.
    """

    params: dict[str, np.ndarray]
    N: int
    Q: np.ndarray
    R: np.ndarray
    L: np.ndarray
    h: np.ndarray
    sigma_z: float
    sigma_r: float
    phi_h: float
    nu: float
    rho_s: float
    c_s: np.ndarray
    L_z: np.ndarray
    L_r: np.ndarray
    nu_o: float
    rho_o: float
    c_o: np.ndarray
    kappa: float
    L_max: float
    w_y_bar: float
    w_bar: float
    w_L: np.ndarray
    a: np.ndarray
    b: np.ndarray
    e_o0: float
    e_inf: float
    s: float
    gain_scale: float | None = None
    model: Any = field(default=None, repr=False)
    row_names: list[str] | None = None
    #: ``"theorem"``: the bounds of ``th:feasibility-stability``; ``"measured"``: the
    #: uncertified design of :func:`controllers.certification.grade.uncertified_certificate`
    #: (no guarantee).
    tightening: str = "theorem"
    #: ``(N + 1, q)``: the part of ``b`` that covers the measured disturbances held over the
    #: horizon (``c_s e_d(i)``, lem:held-disturbance), ``None`` without disturbances; the
    #: uncertified design's measured margins hold them already (measured with them held)
    b_held: np.ndarray | None = None
    #: With an infinite ``s`` (``ν ≥ 1``): ``eq:definition_s`` measured on the model's
    #: linearisation at its steady states
    #: (:class:`~controllers.certification.measured_terminal.MeasuredTerminal`), the terminal
    #: weight of the uncertified design; ``None`` when ``s`` is finite.
    measured: MeasuredTerminal | None = None

    # -- dimensions and derived scalars ----------------------------------------------------
    @property
    def n(self) -> int:
        """Number of GRU states."""
        return int(self.params["U_z"].shape[0])

    @property
    def q(self) -> int:
        """Number of output constraints (rows of ``L``)."""
        return int(self.L.shape[0])

    @property
    def s_measured(self) -> float:
        """The measured terminal weight ``ŝ`` of the uncertified design (:attr:`measured`;
        ``nan`` when ``s`` is finite and none was measured)."""
        return math.nan if self.measured is None else float(self.measured.s)

    @property
    def e_tilde(self) -> float:
        """``ẽ_o = max(ê_o,0, ē_∞)``, the largest ``ê_o,k`` over ``k ≥ 0`` (``eq:def-alpha``;
        ``ê_o,k`` is monotone, ``eq:eo-evolution``)."""
        return max(self.e_o0, self.e_inf)

    def e_o(self, steps: int, e_o0: float | None = None) -> np.ndarray:
        """``ê_o,0 … ê_o,steps`` (``eq:eo-evolution``)."""
        return e_o_sequence(self.e_o0 if e_o0 is None else e_o0, self.rho_o, self.w_bar, steps)

    def tightened_bounds(self, e_o: float) -> np.ndarray:
        """Right-hand sides ``h − a_i ê_o − b_i − w_L`` for ``i = 0..N``, shape ``(N+1, q)``.

        The FHOCP constraint ``eq:optimization-constraint`` is
        ``L (U_o x_{i|k} + b_o) ≤ tightened_bounds(ê_o,k)[i]`` for ``i = 0..N−1``.
        """
        return self.h[None, :] - self.a * e_o - self.b - self.w_L[None, :]

    def alpha_min(self) -> float:
        """Smallest ``α`` satisfying ``eq:condition-recursive-feasibility`` for every
        ``k ≥ 0``: ``ρ_s^N (L_max ẽ_o + w̄) / (1 − ρ_s)``."""
        if self.rho_s >= 1:
            return math.inf
        return self.rho_s**self.N * (self.L_max * self.e_tilde + self.w_bar) / (1 - self.rho_s)

    # -- set-point dependent ---------------------------------------------------------------
    def _set_point(self, y_bar_norm: Sequence[float]) -> tuple[np.ndarray, float]:
        """Margins ``h − ẽ_o a_N − b_N − w_L − L ȳ`` and ``α`` at ``ȳ`` (the last set-point's
        are kept: the governor asks for the same ``ȳ`` several times per step)."""
        y = np.asarray(y_bar_norm, dtype=float).reshape(-1)
        key = y.tobytes()
        memo = self.__dict__.get("_memo")
        if memo is not None and memo[0] == key:
            return memo[1], memo[2]
        m = (-self.L @ y + self.h - self.e_tilde * self.a[self.N] - self.b[self.N]
             - self.w_L)
        pos = self.c_s > 0
        a = float(np.min(m[pos] / self.c_s[pos])) if np.any(pos) else math.inf
        self.__dict__["_memo"] = (key, m, a)
        return m, a

    def _margins(self, y_bar_norm: Sequence[float]) -> np.ndarray:
        return self._set_point(y_bar_norm)[0]

    def alpha(self, y_bar_norm: Sequence[float]) -> float:
        """Terminal set radius ``α`` for the set-point ``ȳ`` (normalised), ``eq:def-alpha``.

        ``α = min_j (−L_(j*) ȳ + h_j − ẽ_o a_N(j) − b_N(j) − w_L(j)) / ‖(L U_o)_(j*)‖∞``.
        Rows with ``‖(L U_o)_(j*)‖∞ = 0`` do not restrict ``α``.
        """
        return self._set_point(y_bar_norm)[1]

    def assumption_1(self, y_bar_norm: Sequence[float]) -> bool:
        """``ass:setpoint``: ``L ȳ < h − ẽ_o a_N − b_N − w_L`` (every row)."""
        return bool(np.all(self._margins(y_bar_norm) > 0))

    def recursive_feasibility(self, y_bar_norm: Sequence[float]) -> bool:
        """``eq:condition-recursive-feasibility`` for all ``k ≥ 0``:
        ``ρ_s^N (L_max ê_o,k + w̄) ≤ α (1 − ρ_s)``.

        ``ê_o,k`` is monotone (``eq:eo-evolution``), so the worst ``k`` has
        ``ê_o,k = ẽ_o = max(ê_o,0, ē_∞)``.
        """
        if self.rho_s >= 1 or not math.isfinite(self.e_tilde):
            return False
        lhs = self.rho_s**self.N * (self.L_max * self.e_tilde + self.w_bar)
        return bool(lhs <= self.alpha(y_bar_norm) * (1 - self.rho_s))

    def admissible_box(self) -> np.ndarray:
        """Right-hand side ``h − ẽ_o a_N − b_N − w_L − α_min c_s`` of the set-points
        satisfying Assumption 1 and ``eq:condition-recursive-feasibility``:
        ``{ȳ : L ȳ ≤ admissible_box()}`` (normalised units, a polytope; a box for the
        four tanks' bounds)."""
        return (self.h - self.e_tilde * self.a[self.N] - self.b[self.N] - self.w_L
                - self.alpha_min() * self.c_s)

    def admissible_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The admissible set-points' bounds per output, ``(lo, hi)`` (normalised; ±∞ where
        no row bounds it): the single-output rows of ``L ȳ ≤`` :meth:`admissible_box`."""
        return box_bounds(self.L, self.admissible_box())

    # -- hypotheses ------------------------------------------------------------------------
    def unusable(self) -> str:
        """Why no robust MPC runs with this model, certified or uncertified, with what would
        fix it (one sentence; ``""`` when one does): the one verdict ``cosim certify``
        prints and saves and ``cosim run`` refuses with.

        With ``ν ≥ 1`` (``th:stability-bonassi``) the contraction ``ρ_s`` of ``lem:Vs`` is
        ``≥ 1``, so the terminal weight ``s`` of ``eq:definition_s`` is infinite; the
        uncertified design then takes the terminal weight measured on the model's
        linearisation at its steady states (:attr:`measured`,
        :mod:`controllers.certification.measured_terminal`). Only when that is infinite too
        (a steady state whose linearisation is unstable) has the FHOCP no finite cost,
        certified or not.
        """
        if self.nu < 1 and math.isfinite(self.s):
            return ""
        found = self.measured
        if found is not None and math.isfinite(found.s):
            return ""   # the uncertified design's terminal weight, measured
        lin = ("and none was measured" if found is None   # a certificate made by hand
               else found.why_infinite(self.model))
        return (f"stability index nu = {self.nu:.4g} >= 1 (th:stability-bonassi), so rho_s = "
                f"{self.rho_s:.4g} >= 1 (lem:Vs) and the terminal weight s (eq:definition_s) "
                f"is infinite, {lin}: the FHOCP has no finite cost, certified or not; fix: "
                f"{NU_FIX}")

    def _design_failures(self) -> list[str]:
        """The design conditions: ν < 1 and ν_o < 1; for the uncertified design
        (``tightening = "measured"``: no contraction assumed, the observer runs the model),
        a finite terminal weight, the theorem's or the measured one."""
        if self.tightening == "measured":
            return [] if math.isfinite(self.s) else [
                "the terminal weight s (eq:definition_s) is infinite, proved or measured"]
        out = []
        if not self.nu < 1:
            out.append(f"δISS condition (th:stability-bonassi) fails: nu = {self.nu:.6g} >= 1")
        if not self.nu_o < 1:
            out.append("observer condition (eq:condition-observer-convergence) fails: "
                       f"nu_o = {self.nu_o:.6g} >= 1")
        return out

    def failures(self, y_bar_norm: Sequence[float] | None = None) -> list[str]:
        """Each failed hypothesis of ``th:feasibility-stability``, as one message each.

        Without a set-point only the design conditions (ν < 1, ν_o < 1; the uncertified
        design's: a finite terminal weight) are checked.
        """
        out = self._design_failures()
        if y_bar_norm is not None and out:
            out.append("set-point checks (Assumption 1, alpha, eq:condition-recursive-"
                       "feasibility) not evaluated: they need the design conditions above")
        elif y_bar_norm is not None:
            a = self.alpha(y_bar_norm)
            if not self.assumption_1(y_bar_norm):
                m = self._margins(y_bar_norm)
                j = int(np.argmin(m))
                row = self.row_names[j] if self.row_names else f"row {j}"
                out.append(f"Assumption 1 (ass:setpoint) fails: constraint {row} has "
                           f"margin {m[j]:.6g} <= 0 (h - e_tilde a_N - b_N - w_L - L y_bar)")
            if not a > 0:
                out.append(f"alpha (eq:def-alpha) = {a:.6g} <= 0: empty terminal set")
            if not self.recursive_feasibility(y_bar_norm):
                out.append("recursive feasibility (eq:condition-recursive-feasibility) fails: "
                           f"alpha = {a:.6g} < alpha_min = {self.alpha_min():.6g} "
                           "= rho_s^N (L_max e_tilde + w_bar)/(1 - rho_s)")
        return out

    def reference(self, y_bar_norm: Sequence[float], *, check: bool = True,
                  kernel: Any = None) -> Reference:
        """Everything the FHOCP needs for a set-point: ``x̄, ū`` and ``α``.

        ``(x̄, ū)`` is the model equilibrium with output ``ȳ`` (:func:`controllers.equilibrium.
        equilibrium`, on ``kernel``'s compiled search when given), ``α`` is ``eq:def-alpha``;
        call again whenever ``ȳ`` changes.

        Raises
        ------
        SetpointError
            When ``ȳ`` is not reachable with ``‖ū‖∞ ≤ 1``, or (``check=True``) when a
            hypothesis of ``th:feasibility-stability`` fails at ``ȳ`` (Assumption 1,
            ``eq:condition-recursive-feasibility``, ν < 1, ν_o < 1); one line naming the
            set-point (physical units when the certificate has its model) and the failures.
        """
        from controllers.equilibrium import describe, equilibrium

        y = np.asarray(y_bar_norm, dtype=float).reshape(-1)
        if check:
            failed = self.failures(y)
            if failed:
                where = describe(self.model, y) if self.model is not None else str(y.tolist())
                raise SetpointError(f"set-point {where}: " + "; ".join(failed))
        x_bar, u_bar = equilibrium(self.model if self.model is not None else self.params, y,
                                   kernel)
        return Reference(y_bar=y, x_bar=x_bar, u_bar=u_bar, alpha=self.alpha(y))

    def ok(self, y_bar_norm: Sequence[float] | None = None) -> bool:
        """``True`` when :meth:`failures` is empty (the same checks, without the messages:
        the reference governor asks at every level)."""
        if self._design_failures():
            return False
        if y_bar_norm is None:
            return True
        return bool(self.assumption_1(y_bar_norm) and self.alpha(y_bar_norm) > 0
                    and self.recursive_feasibility(y_bar_norm))

    # -- output --------------------------------------------------------------------------
    def to_json(self, setpoint: Sequence[float] | None = None) -> dict[str, Any]:
        """A JSON-ready dict with exactly :data:`JSON_KEYS` (arrays as lists).

        ``setpoint`` is ``ȳ`` in normalised units; without it ``alpha``, ``assumption_1``
        and ``recursive_feasibility`` are ``None``. Non-finite scalars (``e_inf`` or ``s``
        when a contraction rate is ≥ 1) are ``None`` too.
        """
        def val(v: Any) -> Any:
            if isinstance(v, np.ndarray):
                return v.tolist()
            if isinstance(v, float) and not math.isfinite(v):
                return None  # JSON has no inf/nan (e.g. e_inf when rho_o >= 1)
            return v

        doc = {k: val(getattr(self, k)) for k in JSON_KEYS[:-3]}
        if setpoint is None:
            doc.update(alpha=None, assumption_1=None, recursive_feasibility=None)
        else:
            doc.update(alpha=val(self.alpha(setpoint)),
                       assumption_1=self.assumption_1(setpoint),
                       recursive_feasibility=self.recursive_feasibility(setpoint))
        return doc


def compute_certificate(model: Any, *, N: int, Q: np.ndarray | None = None,
                        R: np.ndarray | None = None, e_o0: float = 0.02,
                        L_z: np.ndarray | None = None, L_r: np.ndarray | None = None,
                        w_y_bar: float | None = None, gain_scale: float | None = None,
                        L: np.ndarray | None = None, h: np.ndarray | None = None,
                        problem: ControlProblem | None = None) -> Certificate:
    """Compute every certificate quantity for ``model`` (a :class:`GRUModel`).

    Parameters
    ----------
    model : GRUModel
        The δISS GRU (weights and normalisation).
    N : int
        Prediction horizon (the design's: :class:`controllers.mpc_options.MPCOptions`, its
        default the law's spec; the paper's section V takes 15).
    Q, R : arrays, optional
        Cost weights; default ``I_n`` and ``0.01 I_m`` (paper section V).
    e_o0 : float
        ``ê_o,0`` (paper: 0.02), the assumed initial bound of ``‖x_0 − x̂_0‖∞``.
    L_z, L_r : (n, p) arrays, optional
        Observer gains. Default: ``gain_scale ×`` the LP gains
        (:func:`controllers.certification.observer_gains.observer_gains_lp`)
        when ``gain_scale`` is given, else the gains saved in the model file, else the LP
        gains (``gain_scale = 1``).
    w_y_bar : float, optional
        ``w̄_y`` (normalised); default the model file's ``w_y_bar``.
    gain_scale : float, optional
        ``θ`` in ``L = θ·L_LP`` (see
        :func:`controllers.certification.gain_design.choose_gain_scale`).
    L, h : arrays, optional
        Output constraints ``L y ≤ h`` (normalised); default from ``problem``
        (:func:`output_constraints`).
    problem : ControlProblem, optional
        The control problem (its output boxes); default the model file's.

    Raises
    ------
    DesignError
        A bad design argument, or a model without certificate: the update gate saturates
        (σ̄_z rounds to 1, :func:`~controllers.certification.bounds.check_gates`, a
        :class:`~controllers.errors.CertificateError`; the message names the model file when the
        model has a ``source``).
    """
    params = {k: np.asarray(v, dtype=float) for k, v in model.params.items()}
    n, m = params["W_z"].shape
    p = params["U_o"].shape[0]
    # a model holding measured disturbances in its biases (controllers.disturbances): the
    # bounds are the full model's, over the whole box of inputs and disturbances
    held = getattr(model, "held_from", None)
    bound = params if held is None else {k: np.asarray(v, dtype=float)
                                         for k, v in held.params.items()}
    check_gates(bound, getattr(model, "source", None))
    N = horizon(N)
    gain_scale = scalars(e_o0, gain_scale)
    Q = weight(Q, "Q", n, 1.0)
    R = weight(R, "R", m, 0.01)
    L_z, L_r, gain_scale = observer_gains(model, bound, L_z, L_r, gain_scale, n, p)
    if w_y_bar is None:
        w_y_bar = getattr(model, "w_y_bar", None)
        if w_y_bar is None:
            raise DesignError("no w_y_bar: the model file has none; estimate it from data "
                              "(prediction_error.w_y_bar_from_data) or pass w_y_bar")
    w_y_bar = float(w_y_bar)
    row_names = None
    if L is None or h is None:
        L, h = output_constraints(model, problem)
        row_names = constraint_names(model, problem)
    L, h = np.asarray(L, dtype=float), np.asarray(h, dtype=float)
    sz, sr, ph = gate_bounds(bound)
    nu_ = nu(bound)
    rho_s_ = contraction(sz, nu_)
    cs = c_s(params, L)
    nu_o_ = nu_o(bound, L_z, L_r)
    rho_o_ = contraction(sz, nu_o_)
    kap = kappa(bound, L_z, L_r)
    lmax = L_max(bound, L_z, L_r)
    w_bar = kap * w_y_bar
    a, b, b_held = _tightening(model, held, N, rho_o_, rho_s_, lmax, cs, w_bar)
    s = terminal_weight(n, Q, rho_s_)
    measured = None
    if not math.isfinite(s):   # the uncertified design's, measured (ν ≥ 1)
        from controllers.certification.measured_terminal import measured_terminal_weight

        measured = measured_terminal_weight(params, Q)
    return Certificate(
        params=params, N=int(N), Q=Q, R=R, L=L, h=h, sigma_z=sz, sigma_r=sr, phi_h=ph,
        nu=nu_, rho_s=rho_s_, c_s=cs, L_z=L_z, L_r=L_r, nu_o=nu_o_, rho_o=rho_o_,
        c_o=cs.copy(), kappa=kap, L_max=lmax, w_y_bar=w_y_bar, w_bar=w_bar,
        w_L=w_L(L, w_y_bar), a=a, b=b, e_o0=float(e_o0), e_inf=e_inf(rho_o_, w_bar),
        s=s, gain_scale=gain_scale, model=model, row_names=row_names, b_held=b_held,
        measured=measured)


def _tightening(model: Any, held: Any, N: int, rho_o: float, rho_s: float, lmax: float,
                cs: np.ndarray, w_bar: float) -> tuple[np.ndarray, np.ndarray, Any]:
    """``a``, ``b`` (``eq:constraint_tightening_parameters``; with measured disturbances
    ``b`` holds ``b_held``, ``lem:held-disturbance``) and ``b_held``. With a dead time of
    ``K`` samples the FHOCP's stage ``i`` is ``K + i`` steps after the estimate: its
    tightening is the theorem's ``K`` steps on (:mod:`controllers.dead_time`)."""
    from controllers.dead_time import input_delay

    K = input_delay(getattr(held, "problem", None) or getattr(model, "problem", None))
    a, b = tightening_parameters(N + K, rho_o, rho_s, lmax, cs, cs, w_bar)
    a, b = a[K:], b[K:]
    b_held = None
    if held is not None:
        from controllers.disturbances import held_error

        b_held = held_error(held, rho_s, N + K, K)[K:, None] * cs[None, :]
        b = b + b_held
    return a, b, b_held
