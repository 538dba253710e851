"""An electrically heated vessel (pythonfmu, FMI 2.0 CS): SISO, power -> temperature.

A lumped thermal mass with a heat loss that grows with the temperature difference (natural
convection)::

    C dT/dt = P - UA(T) (T - T_amb),   UA(T) = UA0 + UA1 (T - T_amb)

Input: the heater power ``P`` [W] in [0, 2000]; output: the temperature ``T`` [degC]. With
C = 2e4 J/K, UA0 = 30 W/K, UA1 = 0.3 W/K^2, T_amb = 20 degC: the time constant is 150-670 s
and T spans 20-75 degC. Tunable parameters: ``T_amb`` [degC], ``C`` factor ``C_factor``. The
control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import ExamplePlant

C, UA0, UA1 = 2.0e4, 30.0, 0.3


class Heater(ExamplePlant):
    """Heated vessel: power [W] -> temperature [degC]."""

    description = "Heated vessel, P [W] -> T [degC] (pythonfmu)"
    SIGNALS = """
        input      P         W     1000.0  heater power
        output     T         degC  45.0    vessel temperature
        parameter  T_amb     degC  20.0    ambient temperature
        parameter  C_factor  1     1.0     multiplies the heat capacity
    """
    MAX_SUBSTEP = 2.0
    SETTLE = 20000.0

    def rhs(self, x: list[float]) -> list[float]:
        d = x[0] - self.T_amb
        return [(self.P - (UA0 + UA1 * max(d, 0.0)) * d) / (self.C_factor * C)]
