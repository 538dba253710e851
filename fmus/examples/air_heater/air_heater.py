"""An air heater, the plant of issue 62 (pythonfmu, FMI 2.0 CS): SISO, heater power -> outlet
air temperature 60 s late, the inlet air temperature measured.

Modelled on the educational air heater of the University of South-Eastern Norway (F. Haugen,
"Lab rig: Air Heater", techteach.no/lab/air_heater; a Feedback PT326 process trainer is of
the same kind): a fan blows room air through a tube past an electric heater, and the outlet
temperature follows the heater's power as a first-order lag with a transport delay. Haugen's
model, ``tc dT/dt = (T_amb - T) + Kh u(t - td)``, is the energy balance of the tube's air
taken as stirred; written as that balance, with the air's and the wall's losses apart::

    C dT/dt = P(t - 60 s) - m cp (T - T_in) - kw |T - T_in|^(1/3) (T - T_in)

Input: the heater power ``P`` [W] in [0, 2000], reaching the sensor 60 s later (two samples
at Ts = 30 s); output: the outlet temperature ``T`` [degC]; the inlet air temperature
``T_in`` [degC] (the room's, a tunable parameter: the measured disturbance). Sized for the
issue's plant rather than the lab rig's (time constant about 20 s): C = 12 kJ/K (heater,
tube and air), m cp = 22 W/K (22 g/s of air), kw = 0.8 W/K^(4/3) (the tube wall to the room
by natural convection: the mild nonlinearity). Then the time constant is C / (m cp + 4/3 kw
|T - T_in|^(1/3)) = 8.2 min at 10 K and 7.5 min at 75 K above the inlet (15-16 samples), and
2,000 W heat the air 78.7 K. Tunable parameters for campaigns: ``T_in``, ``C_factor``,
``flow_factor``. The control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

from typing import ClassVar

from plant_base import ExamplePlant

C, MCP, KW = 1.2e4, 22.0, 0.8


class AirHeater(ExamplePlant):
    """Air heater: P [W], 60 s transport delay, inlet T_in measured -> outlet T [degC]."""

    SIGNALS = """
        input      P            W     1000.0  heater power, seen at the outlet 60 s later
        output     T            degC  60.0    outlet air temperature
        parameter  T_in         degC  20.0    inlet (room) air temperature
        parameter  C_factor     1     1.0     multiplies the heat capacity
        parameter  flow_factor  1     1.0     multiplies the air flow
    """
    DEAD_TIME: ClassVar[dict[str, float]] = {"P": 60.0}
    MAX_SUBSTEP = 2.0

    def rhs(self, x: list[float]) -> list[float]:
        rise = x[0] - self.T_in
        loss = (self.flow_factor * MCP + KW * abs(rise) ** (1.0 / 3.0)) * rise
        return [(self.P - loss) / (self.C_factor * C)]
