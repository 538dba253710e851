"""The isothermal van de Vusse reactor (pythonfmu, FMI 2.0 CS): SISO, dilution rate -> c_B,
non-minimum phase at its operating point, the feed concentration measured.

The reactions A -> B -> C and 2 A -> D in an isothermal CSTR (van de Vusse, *Chemical
Engineering Science* 19 (1964) 994-997) with the rate constants of Kantor (1986) as used by
Doyle, Ogunnaike & Pearson (*Automatica* 31 (1995) 697-714) and Bequette (*Process Control:
Modeling, Design and Simulation*, 2003, the isothermal CSTR of its MPC chapters; Engell &
Klatt, *ECC* 1993, run the same scheme non-isothermally)::

    dcA/dt = D (cAf - cA) - k1 cA - k3 cA^2
    dcB/dt = -D cB + k1 cA - k2 cB

with k1 = 50 1/h, k2 = 100 1/h, k3 = 10 L/(mol h) and cAf = 10 mol/L (time in hours inside,
divided by 3600). Input: the dilution rate ``D`` = F/V [1/h]; the feed concentration ``cAf``
[mol/L] (measured, not manipulated); output: ``cB`` [mol/L]. The steady c_B rises with D to a
peak of 1.266 mol/L at D = 77.5 1/h and falls beyond it. The operating point is Bequette's,
on the rising side: D = 34.28 1/h (0.5714 1/min), cA = 3.0, cB = 1.117 mol/L, where the
linearised response has poles at -134 and -144 1/h and a zero at +169 1/h (right half-plane):
a step up in D first lowers c_B (the inverse response of a non-minimum-phase plant) before it
rises to the gain 0.00975 mol h/L. Beyond the peak the zero is in the left half-plane. Tunable
parameters for campaigns: ``k1_factor``, ``k2_factor``. The control problem: ``problem.toml``
beside this file.
"""

from __future__ import annotations

from plant_base import ExamplePlant

K1, K2, K3 = 50.0, 100.0, 10.0


class VanDeVusse(ExamplePlant):
    """Van de Vusse CSTR: D [1/h], feed concentration cAf measured -> cB [mol/L]."""

    SIGNALS = """
        input      D          1/h    34.28  dilution rate F/V
        input      cAf        mol/L  10.0   feed concentration of A, measured
        output     cB         mol/L  1.117  concentration of B
        parameter  k1_factor  1      1.0    multiplies k1 (A -> B)
        parameter  k2_factor  1      1.0    multiplies k2 (B -> C)
        state      cA         mol/L  3.0    concentration of A
        state      cB         mol/L  1.117  concentration of B
    """
    MAX_SUBSTEP = 0.5

    def rhs(self, x: list[float]) -> list[float]:
        ca, cb = x
        k1, k2 = self.k1_factor * K1, self.k2_factor * K2
        return [(self.D * (self.cAf - ca) - k1 * ca - K3 * ca * ca) / 3600.0,
                (-self.D * cb + k1 * ca - k2 * cb) / 3600.0]

    def clamp(self, x: list[float]) -> list[float]:
        return [max(0.0, x[0]), max(0.0, x[1])]
