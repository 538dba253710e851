"""Decentralised PI loops tuned from the identified GRU model: RGA pairing and SIMC rules.

A square plant (as many inputs as outputs) gets one PI loop per output without hand-tuning,
in four deterministic steps on the model ``eq:gru`` alone (no plant runs):

1. **Operating point.** The model equilibrium ``(x̄, ū)`` whose output is the middle of the
   control problem's output box (the closest reachable one when the middle is not), or a
   given set-point (:func:`operating_point`; :func:`controllers.equilibrium.equilibrium`).
2. **Steady-state gains and pairing.** ``G = U_o (I − f_x)^{-1} f_u`` at ``(x̄, ū)`` by the
   implicit-function theorem on ``x̄ = f(x̄, ū)`` (:func:`gain_matrix`), scaled to physical
   units; the relative gain array ``Λ = G ∘ (G^{-1})ᵀ`` (Bristol 1966,
   :func:`relative_gain_array`); the pairing of outputs to inputs whose relative gains are
   all positive and closest to one, ``min Σ|λ − 1|`` over every permutation
   (:func:`best_pairing`). No pairing with positive relative gains: refused, naming ``Λ``
   (integral control of a pairing with a negative relative gain is unstable, or becomes so
   when another loop opens or saturates).
3. **One first-order-plus-dead-time model per loop.** The paired channel's response to a
   step of its input (the other inputs held at ``ū``) is simulated on the GRU; the gain
   ``k`` is the step's exact steady-state change (the state equilibrium at the stepped
   input, :func:`~controllers.equilibrium.state_equilibrium`) over the step, ``τ`` and
   delay ``θ`` come from the two-point method of Smith (1972) on the normalised response
   ``s``: ``τ = 1.5 (t₆₃ − t₂₈)``, ``θ = t₆₃ − τ`` where ``s`` first reaches 63.2 % and
   28.3 %, with ``θ ≥ Ts`` (the controller's sample-and-hold: ``u_k`` acts on ``y_{k+1}``)
   (:func:`step_response`, :func:`fit_fopdt`).
4. **SIMC** (Skogestad 2003, :func:`simc`): ``K = τ / (k (τc + θ))``,
   ``Ti = min(τ, 4 (τc + θ))``, with the closed-loop time constant ``τc = θ`` by default
   (Skogestad's choice for tight control with robustness: gain margin ≈ 3, phase margin
   ≈ 47°, sensitivity peak ≈ 1.6); the anti-windup tracking time ``Tt = Ti``. ``K`` has the
   sign of ``k``.

The loops are designed one at a time on the open-loop channel. With the other loops closed
(and perfect) the paired steady-state gain is ``k / λ``: a relative gain above one lowers the
loop gain (slower than designed, more gain margin), one below one raises it; the pairing
keeps ``λ`` near one.

References
----------
E. H. Bristol, "On a new measure of interaction for multivariable process control", IEEE
Transactions on Automatic Control 11(1), 133-134, 1966.

C. L. Smith, *Digital Computer Process Control*, Intext, 1972 (the two-point FOPDT fit).

S. Skogestad, "Simple analytic rules for model reduction and PID controller tuning",
Journal of Process Control 13(4), 291-309, 2003.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers import gru
from controllers.equilibrium import (
    equilibrium,
    equilibrium_for_output,
    jacobians,
    state_equilibrium,
)
from controllers.errors import DesignError
from controllers.problem import PILoop

__all__ = ["MAX_ENUMERATED", "STEP", "LoopTuning", "PITuning", "best_pairing", "fit_fopdt",
           "gain_matrix", "operating_point", "relative_gain_array", "simc", "step_response",
           "tune"]

#: Largest number of loops whose pairings are enumerated (8! = 40,320 permutations).
MAX_ENUMERATED = 8
#: Default input step of the FOPDT fit, normalised units (5 % of the input box's width).
STEP = 0.1
#: Fractions of the final change that define the two points of Smith's method.
_S1, _S2 = 1.0 - math.exp(-1.0 / 3.0), 1.0 - math.exp(-1.0)


@dataclass(frozen=True)
class LoopTuning:
    """One tuned loop: the FOPDT fit of its channel and the SIMC gains.

    Attributes
    ----------
    output, input : str
        The paired output and input.
    relative_gain : float
        ``λ`` of the pair (Bristol 1966).
    k : float
        Steady-state gain of the channel [output unit per input unit].
    tau, theta : float
        FOPDT time constant and delay [s].
    tau_c : float
        SIMC closed-loop time constant [s].
    K, Ti, Tt : float
        PI gain [input unit per output unit], integral and tracking times [s].
    """

    output: str
    input: str
    relative_gain: float
    k: float
    tau: float
    theta: float
    tau_c: float
    K: float
    Ti: float
    Tt: float

    def loop(self) -> PILoop:
        """The loop as the PI baseline takes it."""
        return PILoop(self.output, self.input, self.K, self.Ti, self.Tt)

    def to_dict(self) -> dict[str, Any]:
        return {"output": self.output, "input": self.input, "K": self.K, "Ti": self.Ti,
                "Tt": self.Tt, "relative_gain": self.relative_gain, "k": self.k,
                "tau": self.tau, "theta": self.theta, "tau_c": self.tau_c}


@dataclass(frozen=True)
class PITuning:
    """The result of :func:`tune` (physical units throughout).

    Attributes
    ----------
    output_names, input_names : tuple of str
    y_op, u_op : ndarray
        Outputs and inputs of the operating point.
    requested : ndarray
        The output asked for (the box's middle, or the given set-point); ``y_op`` differs
        when it was not reachable.
    gain : (p, m) ndarray
        Steady-state gain matrix at the operating point.
    rga : (p, m) ndarray
        Its relative gain array.
    loops : tuple of LoopTuning
        One per output, in the outputs' order.
    """

    output_names: tuple[str, ...]
    input_names: tuple[str, ...]
    y_op: np.ndarray
    u_op: np.ndarray
    requested: np.ndarray
    gain: np.ndarray
    rga: np.ndarray
    loops: tuple[LoopTuning, ...]

    def pi_loops(self) -> tuple[PILoop, ...]:
        """The loops as the PI baseline takes them."""
        return tuple(lt.loop() for lt in self.loops)

    def to_dict(self) -> dict[str, Any]:
        """A JSON record (``summary.json``): operating point, ``G``, ``Λ``, the loops."""
        return {"method": "pairing by the RGA (Bristol 1966); FOPDT by Smith's two-point "
                          "method on the GRU's step responses; SIMC (Skogestad 2003), Tt = Ti",
                "operating_point": {
                    "outputs": dict(zip(self.output_names, map(float, self.y_op), strict=True)),
                    "requested": dict(zip(self.output_names, map(float, self.requested),
                                          strict=True)),
                    "inputs": dict(zip(self.input_names, map(float, self.u_op), strict=True))},
                "outputs": list(self.output_names), "inputs": list(self.input_names),
                "gain_matrix": self.gain.tolist(), "rga": self.rga.tolist(),
                "loops": [lt.to_dict() for lt in self.loops]}


def _params(model: Any) -> dict[str, np.ndarray]:
    return {k: np.asarray(v, dtype=float) for k, v in model.params.items()}


def operating_point(model: Any, setpoint: Sequence[float] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The equilibrium ``(x̄, ū, ȳ)`` the loops are tuned at (normalised units).

    Parameters
    ----------
    model : GRUModel
    setpoint : (p,) array, optional
        Outputs in physical units: the equilibrium must reach them. Default: the middle of
        the problem's output boxes (the model's output offsets without a problem), or the
        reachable equilibrium closest to it.

    Raises
    ------
    UnreachableSetpoint
        A given set-point that no input inside the box holds.
    """
    if setpoint is not None:
        y = model.normalize_y(np.asarray(setpoint, dtype=float).reshape(-1))
        x, u = equilibrium(model, y)
    else:
        x, u = equilibrium_for_output(model, model.normalize_y(_middle(model)))
    p = _params(model)
    return x, u, gru.output(p, x)


def gain_matrix(model: Any, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Steady-state gains ``∂ȳ/∂ū`` at the equilibrium ``(x, u)``, physical units.

    By the implicit-function theorem on ``x̄ = f(x̄, ū)``: ``∂x̄/∂ū = (I − f_x)^{-1} f_u``
    (``I − f_x`` is invertible when ``f(·, ū)`` contracts), ``∂ȳ/∂ū = U_o ∂x̄/∂ū`` in
    normalised units, then ``G_ij · y_scale_i / u_scale_j``.
    """
    p = _params(model)
    f_x, f_u = jacobians(p, x, u)
    g = p["U_o"] @ np.linalg.solve(np.eye(x.shape[0]) - f_x, f_u)
    return g * np.asarray(model.y_scale, float)[:, None] / np.asarray(model.u_scale, float)[None]


def relative_gain_array(gain: np.ndarray) -> np.ndarray:
    """Bristol's relative gain array ``Λ = G ∘ (G^{-1})ᵀ`` of a square gain matrix.

    ``λ_ij`` is the gain from input ``j`` to output ``i`` with every other loop open over
    the same gain with every other output held by perfect control (Bristol 1966). Rows and
    columns sum to one; ``Λ`` does not depend on the units.

    Raises
    ------
    DesignError
        ``G`` is not square or is singular (no input combination moves every output).
    """
    gain = np.asarray(gain, dtype=float)
    if gain.ndim != 2 or gain.shape[0] != gain.shape[1]:
        raise DesignError(f"the relative gain array needs a square gain matrix, got shape "
                          f"{gain.shape}")
    if np.linalg.cond(gain) > 1e12:
        raise DesignError(f"the steady-state gain matrix {_fmt(gain)} is singular: no "
                          "decentralised pairing controls every output")
    return gain * np.linalg.inv(gain).T


def best_pairing(rga: np.ndarray, output_names: Sequence[str] | None = None,
                 input_names: Sequence[str] | None = None) -> tuple[int, ...]:
    """The pairing ``perm`` (output ``i`` with input ``perm[i]``) whose relative gains are
    all positive and closest to one, ``min Σ_i |λ_i,perm[i] − 1|``.

    Every permutation is tried, in lexicographic order (the first of equal sums wins:
    deterministic).

    Raises
    ------
    DesignError
        Every pairing has a non-positive relative gain (the message names ``Λ``), or there
        are more than :data:`MAX_ENUMERATED` loops.
    """
    rga = np.asarray(rga, dtype=float)
    n = rga.shape[0]
    if n > MAX_ENUMERATED:
        raise DesignError(f"{n} loops: pairings are chosen for at most {MAX_ENUMERATED} "
                          "(give the loops)")
    best, best_cost = None, math.inf
    for perm in itertools.permutations(range(n)):
        lam = rga[np.arange(n), perm]
        if np.all(lam > 0):
            cost = float(np.sum(np.abs(lam - 1.0)))
            if cost < best_cost - 1e-12:
                best, best_cost = perm, cost
    if best is None:
        outs = ", ".join(output_names) if output_names else f"{n} outputs"
        ins = ", ".join(input_names) if input_names else f"{n} inputs"
        raise DesignError(f"no pairing of the outputs ({outs}) with the inputs ({ins}) has "
                          f"positive relative gains: RGA {_fmt(rga)} (rows outputs, columns "
                          "inputs); a decentralised PI cannot be tuned (give the loops)")
    return tuple(int(j) for j in best)


def step_response(model: Any, x: np.ndarray, u: np.ndarray, j: int, delta: float,
                  steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Response of the model from the equilibrium ``(x, u)`` to a step ``delta`` of input
    ``j`` (normalised) applied at ``k = 0``.

    Returns
    -------
    y : (steps + 1, p) ndarray
        Outputs ``y_0 … y_steps`` (normalised; ``y_0`` is the equilibrium's).
    y_final : (p,) ndarray
        The exact steady state after the step (normalised).
    """
    p = _params(model)
    u1 = np.array(u, dtype=float)
    u1[j] += delta
    xs = np.empty((steps + 1, x.shape[0]))
    xs[0] = x
    for k in range(steps):
        xs[k + 1] = gru.step(p, xs[k], u1)
    x_final = state_equilibrium(p, u1, xs[-1])
    return xs @ p["U_o"].T + p["b_o"], gru.output(p, x_final)


def fit_fopdt(s: np.ndarray, Ts: float) -> tuple[float, float]:
    """``(τ, θ)`` of a first-order-plus-dead-time fit to the normalised step response ``s``
    (``s_0 = 0`` before the step, ``s → 1``) sampled every ``Ts``.

    Smith's two-point method: ``t₁`` and ``t₂`` where ``s`` first reaches 28.3 % and 63.2 %
    (linear interpolation between samples), ``τ = 1.5 (t₂ − t₁)``, ``θ = t₂ − τ``; then
    ``θ ≥ Ts`` (a discrete loop's input acts one sample later) and ``τ ≥ Ts / 2``.
    An inverse response first moves away from one: it counts as delay (Skogestad's half
    rule treats it alike).

    Raises
    ------
    DesignError
        ``s`` never reaches 63.2 %.
    """
    t1, t2 = _crossing(s, _S1, Ts), _crossing(s, _S2, Ts)
    if t2 is None or t1 is None:
        raise DesignError(f"the step response reaches {float(np.max(s)):.0%} of its final "
                          f"change within {len(s) - 1} samples, not 63 %")
    tau = 1.5 * (t2 - t1)
    theta = t2 - tau
    return max(tau, 0.5 * Ts), max(theta, Ts)


def _crossing(s: np.ndarray, level: float, Ts: float) -> float | None:
    above = np.nonzero(s >= level)[0]
    if above.size == 0:
        return None
    k = int(above[0])
    if k == 0:
        return 0.0
    a, b = float(s[k - 1]), float(s[k])
    return Ts * (k - 1 + (level - a) / (b - a))


def simc(k: float, tau: float, theta: float, tau_c: float | None = None
         ) -> tuple[float, float, float]:
    """SIMC PI settings (Skogestad 2003) for ``k e^{−θ s} / (τ s + 1)``.

    ``K = τ / (k (τc + θ))``, ``Ti = min(τ, 4 (τc + θ))``; ``τc = θ`` by default (tight
    control, robust: gain margin ≈ 3, phase margin ≈ 47°). ``K`` has the sign of ``k``.

    Returns
    -------
    K : float
        Proportional gain [input unit per output unit].
    Ti : float
        Integral time [s].
    tau_c : float
        The closed-loop time constant used [s].
    """
    if not (math.isfinite(k) and k != 0.0):
        raise DesignError(f"SIMC needs a non-zero finite process gain, got k = {k!r}")
    tau_c = theta if tau_c is None else float(tau_c)
    if not (math.isfinite(tau_c) and tau_c > 0):
        raise DesignError(f"tau_c must be a positive number of seconds, got {tau_c!r}")
    return tau / (k * (tau_c + theta)), min(tau, 4.0 * (tau_c + theta)), tau_c


def tune(model: Any, setpoint: Sequence[float] | None = None, tau_c: float | None = None,
         delta: float = STEP) -> PITuning:
    """Decentralised PI loops for a square GRU model (see the module docstring).

    Parameters
    ----------
    model : GRUModel
        The identified model, with its control problem (for the output box).
    setpoint : (p,) array, optional
        Operating point's outputs, physical units (default: the output box's middle).
    tau_c : float, optional
        SIMC closed-loop time constant of every loop [s] (default: each loop's ``θ``).
    delta : float
        Input step of the FOPDT fit, normalised units; applied towards the side of the
        input box with more room.

    Raises
    ------
    DesignError
        A non-square model, a singular gain matrix, no pairing with positive relative
        gains, a step response that does not settle.
    UnreachableSetpoint
        ``setpoint`` is not an equilibrium output with inputs in the box.
    """
    if model.m != model.p:
        raise DesignError(f"a decentralised PI needs as many inputs as outputs; the model "
                          f"has {model.m} inputs and {model.p} outputs")
    if not (math.isfinite(delta) and 0 < delta <= 1):
        raise DesignError(f"delta must be in (0, 1] (normalised input step), got {delta!r}")
    outs, ins = tuple(model.output_names), tuple(model.input_names)
    x, u, y = operating_point(model, setpoint)
    requested = np.asarray(setpoint if setpoint is not None else _middle(model), dtype=float)
    gain = gain_matrix(model, x, u)
    rga = relative_gain_array(gain)
    perm = best_pairing(rga, outs, ins)
    steps = _horizon(model, x, u)
    loops = []
    for i, j in enumerate(perm):
        d = delta if u[j] <= 0 else -delta
        resp, final = step_response(model, x, u, j, d, steps)
        dy = final[i] - y[i]
        k = float(dy * model.y_scale[i] / (d * model.u_scale[j]))
        if abs(dy) < 1e-9:
            raise DesignError(f"{outs[i]} does not respond to a step of {ins[j]} at the "
                              "operating point (zero gain)")
        try:
            tau, theta = fit_fopdt((resp[:, i] - y[i]) / dy, model.Ts)
        except DesignError as exc:
            raise DesignError(f"{outs[i]} <- {ins[j]}: {exc}") from None
        K, Ti, tc = simc(k, tau, theta, tau_c)
        loops.append(LoopTuning(outs[i], ins[j], float(rga[i, j]), k, tau, theta, tc, K, Ti,
                                Ti))
    return PITuning(outs, ins, model.denormalize_y(y), model.denormalize_u(u), requested,
                    gain, rga, tuple(loops))


def _middle(model: Any) -> np.ndarray:
    problem = getattr(model, "problem", None)
    if problem is None:
        return np.asarray(model.y_offset, dtype=float)
    return np.array([0.5 * (c.min + c.max) for c in problem.outputs])


def _horizon(model: Any, x: np.ndarray, u: np.ndarray) -> int:
    """Samples to simulate: ten times the slowest mode of the linearisation, 200 to 20,000."""
    f_x, _ = jacobians(_params(model), x, u)
    rho = float(np.max(np.abs(np.linalg.eigvals(f_x))))
    if rho >= 1.0:
        raise DesignError("the model is not contracting at the operating point "
                                  f"(spectral radius of ∂f/∂x {rho:.4g} ≥ 1): its step "
                                  "responses do not settle")
    slow = -1.0 / math.log(rho) if rho > 0 else 1.0
    return int(min(20000, max(200, math.ceil(10 * slow))))


def _fmt(a: np.ndarray) -> str:
    return "[" + "; ".join(" ".join(f"{v:.3g}" for v in row) for row in a) + "]"
