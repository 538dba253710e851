"""A three-zone electric furnace (pythonfmu, FMI 2.0 CS): 3 x 3, each zone coupled to its
neighbours.

The two-zone furnace of ``furnace/furnace.py`` with a third zone after the second, written
here again rather than imported from its script (FMUs built by pythonfmu and loaded in one
Python host share their scripts' modules by name, see ``heater_dead_time.py``)::

    C dTi/dt = Pi - UA (Ti - T_amb) - E ((Ti + 273.15)^4 - (T_amb + 273.15)^4)
               + K (T(i-1) - Ti) + K (T(i+1) - Ti)        (the terms of existing neighbours)

Inputs: the heater powers ``P1``, ``P2``, ``P3`` [W] in [0, 3000]; outputs: the zone
temperatures ``T1``, ``T2``, ``T3`` [degC]. The constants are the two-zone furnace's
(C = 1e4 J/K, UA = 5 W/K, K = 12 W/K, E = 1.2e-8 W/K^4): the middle zone exchanges heat
with both others, the zones settle in 10-30 min. Tunable parameters: ``T_amb`` [degC],
``K_factor``, ``C_factor``. The control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import FurnacePlant


class Furnace3(FurnacePlant):
    """Three-zone furnace: heater powers -> zone temperatures."""

    description = "Three-zone furnace, P1, P2, P3 [W] -> T1, T2, T3 [degC] (pythonfmu)"
    SIGNALS = """
        input      P1        W     1000.0  heater power of zone 1
        input      P2        W     1000.0  heater power of zone 2
        input      P3        W     1000.0  heater power of zone 3
        output     T1        degC  150.0   temperature of zone 1
        output     T2        degC  150.0   temperature of zone 2
        output     T3        degC  150.0   temperature of zone 3
    """ + FurnacePlant.AMBIENT + FurnacePlant.PARAMETERS

    def rhs(self, x: list[float]) -> list[float]:
        amb = self.T_amb + 273.15
        k, c = self.K_factor * self.K, self.C_factor * self.C
        power = (self.P1, self.P2, self.P3)
        out = []
        for i, t in enumerate(x):
            q = power[i] - self.UA * (t - self.T_amb) - self.E * ((t + 273.15) ** 4 - amb ** 4)
            if i > 0:
                q += k * (x[i - 1] - t)
            if i < 2:
                q += k * (x[i + 1] - t)
            out.append(q / c)
        return out
