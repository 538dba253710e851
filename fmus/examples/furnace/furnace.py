"""A two-zone electric furnace (pythonfmu, FMI 2.0 CS): 2 x 2, strongly coupled.

Two heated zones of one furnace exchange heat through the wall between them, lose it to the
room by convection and, hot, by radiation::

    C dT1/dt = P1 - UA (T1 - T_amb) - K (T1 - T2) - E ((T1 + 273.15)^4 - (T_amb + 273.15)^4)
    C dT2/dt = P2 - UA (T2 - T_amb) + K (T1 - T2) - E ((T2 + 273.15)^4 - (T_amb + 273.15)^4)

Inputs: the heater powers ``P1``, ``P2`` [W] in [0, 3000]; outputs: the zone temperatures
``T1``, ``T2`` [degC]. With C = 1e4 J/K, UA = 5 W/K, K = 12 W/K (the zones are coupled more
strongly than they lose heat: a decentralised loop on one zone is disturbed by the other's),
E = 1.2e-8 W/K^4: the zones span 20-330 degC, the fast (difference) mode settles in
about 10 min, the slow (common) mode in 20-30 min, and the radiation makes the gain fall by
half from cold to hot. Tunable parameters: ``T_amb`` [degC], ``K_factor`` (multiplies K),
``C_factor`` (multiplies C). The control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import FurnacePlant


class Furnace(FurnacePlant):
    """Two-zone furnace: heater powers -> zone temperatures."""

    description = "Two-zone furnace, P1, P2 [W] -> T1, T2 [degC] (pythonfmu)"
    SIGNALS = """
        input      P1        W     1000.0  heater power of zone 1
        input      P2        W     1000.0  heater power of zone 2
        output     T1        degC  150.0   temperature of zone 1
        output     T2        degC  150.0   temperature of zone 2
    """ + FurnacePlant.AMBIENT + FurnacePlant.PARAMETERS

    def rhs(self, x: list[float]) -> list[float]:
        t1, t2 = x
        amb = self.T_amb + 273.15
        q12 = self.K_factor * self.K * (t1 - t2)
        ua, e = self.UA, self.E
        d1 = self.P1 - ua * (t1 - self.T_amb) - q12 - e * ((t1 + 273.15) ** 4 - amb ** 4)
        d2 = self.P2 - ua * (t2 - self.T_amb) + q12 - e * ((t2 + 273.15) ** 4 - amb ** 4)
        return [d1 / (self.C_factor * self.C), d2 / (self.C_factor * self.C)]
