"""A slow thermal process, a heated building zone (pythonfmu, FMI 2.0 CS): SISO, heating power
-> indoor temperature, the outdoor temperature measured; time constant 43-56 samples.

The two-state resistor-capacitor model "TiTe" of P. Bacher and H. Madsen, "Identifying
suitable models for the heat dynamics of buildings", *Energy and Buildings* 43 (2011)
1511-1522 (the indoor air and furnishings ``Ti`` with a small capacity, the building envelope
``Te`` with a large one; also Madsen & Holst, *Energy and Buildings* 22 (1995) 67-79)::

    Ci dTi/dt = (Te - Ti) / Rie + P
    Ce dTe/dt = (Ti - Te) / Rie - G(Te - Ta) (Te - Ta),   G(d) = (1 + 0.005 |d|) / Rea

in hours (divided by 3600 for seconds), capacities in kWh/K, resistances in K/kW. The values
are of the size Bacher & Madsen identified for their single-storey test building (FlexHouse,
Risoe): Ci = 0.1, Ce = 3.0 kWh/K, Rie = 0.9, Rea = 4.5 K/kW. The mild nonlinearity is this
example's own: the envelope's outer film coefficient grows by 0.5 % per kelvin of difference
(natural convection), as the heated vessel's loss does. Input: the heating power ``P`` [kW]
in [0, 8]; the outdoor temperature ``Ta`` [degC] (the measured disturbance, a tunable
parameter); output: the indoor temperature ``Ti`` [degC]. The slow (envelope) mode has the
time constant 14.0 h at small differences and 10.7 h at 30 K (56 and 43 samples of 15 min),
the fast (air) mode 5.2 min; the gain falls from 5.4 to 4.4 K/kW. Tunable parameters for
campaigns: ``Ce_factor``, ``Rea_factor``. The control problem: ``problem.toml`` beside this
file.
"""

from __future__ import annotations

from plant_base import ExamplePlant

CI, CE, RIE, REA, FILM = 0.1, 3.0, 0.9, 4.5, 0.005


class SlowThermal(ExamplePlant):
    """Building zone (TiTe): P [kW], outdoor Ta measured -> indoor Ti [degC]."""

    SIGNALS = """
        input      P           kW    4.0   heating power
        output     Ti          degC  20.2  indoor temperature
        parameter  Ta          degC  0.0   outdoor temperature (measured)
        parameter  Ce_factor   1     1.0   multiplies the envelope's heat capacity
        parameter  Rea_factor  1     1.0   multiplies the envelope's resistance to outside
        state      Ti          degC  20.2  indoor air and furnishings
        state      Te          degC  16.6  building envelope
    """
    MAX_SUBSTEP = 60.0

    def rhs(self, x: list[float]) -> list[float]:
        ti, te = x
        inner = (te - ti) / RIE
        d = te - self.Ta
        outer = (1.0 + FILM * abs(d)) * d / (self.Rea_factor * REA)
        return [(inner + self.P) / (CI * 3600.0),
                (-inner - outer) / (self.Ce_factor * CE * 3600.0)]
