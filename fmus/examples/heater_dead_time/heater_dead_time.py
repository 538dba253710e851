"""A heated vessel fed through a pipe (pythonfmu, FMI 2.0 CS): the heater of
``heater/heater.py`` whose power reaches the vessel 40 s late (a transport delay of two
samples at Ts = 20 s), with its ambient temperature as a measured disturbance.

The heater's equations, written here again rather than imported from its script: FMUs built by
pythonfmu and loaded in one Python host share their scripts' modules by name, so a script
importing another's would get whichever the host loaded first (measured: a crash when both
heaters ran in one process)::

    C dT/dt = P(t - 40 s) - UA(T) (T - T_amb),   UA(T) = UA0 + UA1 (T - T_amb)

Input: the power ``P`` [W] in [0, 2000] (seen 40 s late); output: ``T`` [degC]; tunable
parameters: ``T_amb`` [degC] (the measured disturbance of ``problem.toml``), ``C_factor``.
"""

from __future__ import annotations

from typing import ClassVar

from plant_base import ExamplePlant

C, UA0, UA1 = 2.0e4, 30.0, 0.3


class HeaterDeadTime(ExamplePlant):
    """Heated vessel with a 40 s transport delay on its power."""

    description = "Heated vessel, P [W] (40 s dead time) -> T [degC] (pythonfmu)"
    SIGNALS = """
        input      P         W     1000.0  heater power, reaching the vessel 40 s later
        output     T         degC  45.0    vessel temperature
        parameter  T_amb     degC  20.0    ambient temperature
        parameter  C_factor  1     1.0     multiplies the heat capacity
    """
    DEAD_TIME: ClassVar[dict[str, float]] = {"P": 40.0}
    MAX_SUBSTEP = 2.0
    SETTLE = 20000.0

    def rhs(self, x: list[float]) -> list[float]:
        d = x[0] - self.T_amb
        return [(self.P - (UA0 + UA1 * max(d, 0.0)) * d) / (self.C_factor * C)]
