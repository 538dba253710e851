"""An exothermic continuous stirred-tank reactor, A -> B (pythonfmu, FMI 2.0 CS): 2 x 2.

The classic jacketed CSTR (Seborg et al., *Process Dynamics and Control*, with a milder
reaction heat so that it is open-loop stable over its whole input box)::

    dCA/dt = F/V (CAf - CA) - k(T) CA
    dT/dt  = F/V (Tf - T) + (-dH)/(rho Cp) k(T) CA - UA/(V rho Cp) (T - Tc)
    k(T)   = k0_factor * k0 exp(-E/(R T))

in minutes (divided by 60 for seconds). Inputs: the feed flow ``F`` [L/min], the coolant
temperature ``Tc`` [K]; outputs: the concentration ``CA`` [mol/L] and the temperature ``T``
[K]. Over F in [50, 150] L/min and Tc in [290, 350] K the time constants are 18-116 s and
CA spans 0.19-0.97 mol/L, T 300-372 K. Tunable parameters for campaigns: ``k0_factor``,
``UA_factor``, ``CAf``, ``Tf``. The control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

import math

from plant_base import ExamplePlant

V, RHO, CP, DH, E_R, K0, UA = 100.0, 1000.0, 0.239, -2.0e4, 8750.0, 7.2e10, 5.0e4


class CSTR(ExamplePlant):
    """Jacketed exothermic CSTR: feed flow and coolant temperature -> CA and T."""

    description = "Exothermic CSTR, F [L/min] and Tc [K] -> CA [mol/L] and T [K] (pythonfmu)"
    SIGNALS = """
        input      F          L/min  100.0  feed flow
        input      Tc         K      320.0  coolant temperature
        output     CA         mol/L  0.8    concentration of A
        output     T          K      330.0  reactor temperature
        parameter  k0_factor  1      1.0    multiplies the rate constant k0
        parameter  UA_factor  1      1.0    multiplies the heat transfer UA of the jacket
        parameter  CAf        mol/L  1.0    feed concentration
        parameter  Tf         K      340.0  feed temperature
    """
    MAX_SUBSTEP = 0.5
    SETTLE = 3000.0

    def rhs(self, x: list[float]) -> list[float]:
        ca, t = x
        k = self.k0_factor * K0 * math.exp(-E_R / t)
        f_v = self.F / V
        dca = f_v * (self.CAf - ca) - k * ca
        dt = (f_v * (self.Tf - t) + (-DH) / (RHO * CP) * k * ca
              - self.UA_factor * UA / (V * RHO * CP) * (t - self.Tc))
        return [dca / 60.0, dt / 60.0]

    def clamp(self, x: list[float]) -> list[float]:
        return [max(0.0, x[0]), max(1.0, x[1])]
