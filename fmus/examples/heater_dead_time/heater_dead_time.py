"""A heated vessel fed through a pipe (pythonfmu, FMI 2.0 CS): the heater of
``heater/heater.py`` whose power reaches the vessel 40 s late (a transport delay of two
samples at Ts = 20 s), with its ambient temperature as a measured disturbance.

The heater's equations (its script is bundled beside this one)::

    C dT/dt = P(t - 40 s) - UA(T) (T - T_amb),   UA(T) = UA0 + UA1 (T - T_amb)

Input: the power ``P`` [W] in [0, 2000] (seen 40 s late); output: ``T`` [degC]; tunable
parameters: ``T_amb`` [degC] (the measured disturbance of ``problem.toml``), ``C_factor``.
"""

from __future__ import annotations

from typing import ClassVar

from heater import Heater


class HeaterDeadTime(Heater):
    """Heated vessel with a 40 s transport delay on its power."""

    description = "Heated vessel, P [W] (40 s dead time) -> T [degC] (pythonfmu)"
    DEAD_TIME: ClassVar[dict[str, float]] = {"P": 40.0}
