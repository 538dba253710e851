"""The contraction rate a trained GRU may have, derived from the data.

The robust MPC pays for a slow certified contraction: the terminal weight
``s = n λ_max(Q)/(1 − ρ_s²)`` of ``eq:definition_s`` and every tightening term that sums
``ρ_s^i`` over the horizon (``eq:constraint_tightening_parameters``; the held measured
disturbance's, :func:`controllers.disturbances.held_error`) grow as ``ρ_s`` approaches 1, where
``ρ_s = σ̄_z + (1 − σ̄_z) ν`` (``lem:Vs``). Trained with only ``ν ≤ 0.98``, a GRU ends with
``ρ_s`` within a few 1e-4 of 1 whatever its plant: ``σ̄_z`` and ``ν`` both drift to their caps.
Yet a model needs no slower contraction than its plant's: every linearisation of a GRU
contracting at ``ρ_s`` has its poles inside the disc of radius ``ρ_s``, so ``ρ_s`` only has to
exceed the modulus of the plant's slowest pole.

:func:`rho_max` reads that pole from the ARX baseline fitted on the same training rows
(:mod:`controllers.identification.linear`; the largest modulus of the eigenvalues of its
autoregressive part) and allows the model :data:`SLACK` times the plant's slowest time
constant: ``ρ_max = 1 − (1 − λ)/SLACK``, at least :data:`RHO_FLOOR`. Training keeps
``ρ_s ≤ ρ_max`` at every step (:func:`controllers.identification.training.constrain`), the
update gate's bound ``σ̄_z`` below :func:`sigma_cap` so that ``ν`` keeps at least half its
range.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.identification.linear import ARXModel

__all__ = ["RHO_FLOOR", "SLACK", "rho_max", "sigma_cap", "slowest_pole"]

#: The model may contract this many times slower than the plant's slowest mode (its time
#: constant −1/ln ρ this many times the plant's).
SLACK = 2.0
#: The smallest derived ``ρ_max``: ``σ̄_z ≥ ½`` for any GRU, so ``ρ_s`` below about 0.75
#: leaves the recurrence no room (:func:`sigma_cap`).
RHO_FLOOR = 0.8


def slowest_pole(arx: ARXModel) -> float:
    """The largest modulus of the poles of ``arx``: the eigenvalues of the companion matrix
    of ``y_t = Σ_{i=1..na} A_i y_{t−i}`` (``p·na`` of them)."""
    theta = np.asarray(arx.theta, dtype=float)
    p = theta.shape[1]
    lags = [theta[1 + i * p:1 + (i + 1) * p].T for i in range(arx.na)]
    companion = np.zeros((arx.na * p, arx.na * p))
    companion[:p] = np.hstack(lags)
    companion[p:, :-p] = np.eye((arx.na - 1) * p)
    return float(np.max(np.abs(np.linalg.eigvals(companion))))


def rho_max(arx: ARXModel | None) -> float:
    """The contraction cap derived from the ARX baseline (module docstring); ``0`` (no cap)
    when there is no baseline or its slowest pole is not inside the unit disc."""
    if arx is None:
        return 0.0
    pole = slowest_pole(arx)
    if not (math.isfinite(pole) and pole < 1.0):
        return 0.0
    return float(max(1.0 - (1.0 - pole) / SLACK, RHO_FLOOR))


def sigma_cap(rho: float) -> float:
    """The bound of ``σ̄_z`` under a contraction cap ``rho`` (``½ < rho < 1``): ``2 rho − 1``,
    where ``ν`` may still reach ``½`` (``ρ_s = σ̄_z + (1 − σ̄_z) ν ≤ rho``), so that neither the
    gates nor the recurrence ``U_h`` is starved (with ``rho`` derived by :func:`rho_max`, the
    ARX model's slowest pole); at least ``½``, the smallest ``σ̄_z`` of any GRU (``z = ½``,
    ``W_z = 0``, ``b_z = 0``)."""
    return max(0.5, 2.0 * rho - 1.0)
