"""A continuous two-zone furnace with its product throughput measured (pythonfmu, FMI 2.0 CS):
the furnace of ``furnace/furnace.py`` with a load, 2 x 2 with one measured disturbance.

The furnace's equations, written here again rather than imported from its script (FMUs built
by pythonfmu and loaded in one Python host share their scripts' modules by name, see
``heater_dead_time.py``), with the product passing through both zones: it enters zone 1 at
room temperature, leaves it at ``T1``, enters zone 2 and leaves at ``T2``, taking the heat
``G (T_in - T_out)`` of each zone, ``G = F c_p / 3600`` [W/K] for a throughput ``F`` [kg/h]::

    C dT1/dt = P1 - UA (T1 - T_amb) - K (T1 - T2) - E ((T1 + 273.15)^4 - (T_amb + 273.15)^4)
               - G (T1 - T_amb)
    C dT2/dt = P2 - UA (T2 - T_amb) + K (T1 - T2) - E ((T2 + 273.15)^4 - (T_amb + 273.15)^4)
               - G (T2 - T1)

Inputs: the heater powers ``P1``, ``P2`` [W] in [0, 3000] and the throughput ``F_load``
[kg/h] in [0, 50] (the load: set by production, measured, not moved by the controller; 50 kg/h
at 170 degC draw about 1,000 W from zone 1, half the power it needs); outputs: ``T1``, ``T2``
[degC]. The constants are the
furnace's (C = 1e4 J/K, UA = 5 W/K, K = 12 W/K, E = 1.2e-8 W/K^4) and c_p = 500 J/(kg K).
Tunable parameters: ``T_amb`` [degC], ``K_factor``, ``C_factor``. The control problem:
``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import FurnacePlant

CP = 500.0   # the product's heat capacity [J/(kg K)]


class FurnaceLoad(FurnacePlant):
    """Two-zone furnace with a measured product throughput."""

    description = ("Two-zone furnace with a load, P1, P2 [W], F_load [kg/h] -> T1, T2 [degC] "
                   "(pythonfmu)")
    SIGNALS = """
        input      P1        W     1000.0  heater power of zone 1
        input      P2        W     1000.0  heater power of zone 2
        input      F_load    kg/h  10.0    product throughput (the load), measured
        output     T1        degC  150.0   temperature of zone 1
        output     T2        degC  150.0   temperature of zone 2
        parameter  T_amb     degC  20.0    room temperature, the product's inlet""" + (
        FurnacePlant.PARAMETERS)

    def rhs(self, x: list[float]) -> list[float]:
        t1, t2 = x
        amb, g = self.T_amb + 273.15, self.F_load * CP / 3600.0
        q12 = self.K_factor * self.K * (t1 - t2)
        rad1, rad2 = ((t + 273.15) ** 4 - amb ** 4 for t in (t1, t2))
        d1 = self.P1 - self.UA * (t1 - self.T_amb) - q12 - self.E * rad1 - g * (t1 - self.T_amb)
        d2 = self.P2 - self.UA * (t2 - self.T_amb) + q12 - self.E * rad2 - g * (t2 - t1)
        return [d1 / (self.C_factor * self.C), d2 / (self.C_factor * self.C)]
