"""The pH neutralisation process of Henson & Seborg (pythonfmu, FMI 2.0 CS): SISO, base
flow -> pH, the buffer flow measured; a strongly nonlinear gain.

M. A. Henson and D. E. Seborg, "Adaptive nonlinear control of a pH neutralization process",
*IEEE Transactions on Control Systems Technology* 2(3) (1994) 169-182 (also their *Nonlinear
Process Control*, Prentice Hall, 1997, ch. 4): an acid stream ``q1`` (HNO3), a buffer stream
``q2`` (NaHCO3) and a base stream ``q3`` (NaOH with a little NaHCO3) mixed in a tank that
drains through a valve. With the reaction invariants ``Wa = [H+] - [OH-] - [HCO3-] -
2 [CO3--]`` and ``Wb = [H2CO3] + [HCO3-] + [CO3--]`` of the effluent and the level ``h``::

    A dh/dt    = q1 + q2 + q3 - Cv (h + z)^n
    A h dWa/dt = q1 (Wa1 - Wa) + q2 (Wa2 - Wa) + q3 (Wa3 - Wa)
    A h dWb/dt = q1 (Wb1 - Wb) + q2 (Wb2 - Wb) + q3 (Wb3 - Wb)
    0 = Wa + 10^(pH - 14) - 10^(-pH) + Wb (1 + 2 10^(pH - pK2)) / (1 + 10^(pK1 - pH)
        + 10^(pH - pK2))                                       (the titration curve)

with the published values: A = 207 cm2, z = 11.5 cm, n = 0.607, pK1 = 6.35, pK2 = 10.33,
Wa1 = 3e-3, Wb1 = 0 (acid), Wa2 = -3e-2, Wb2 = 3e-2 (buffer), Wa3 = -3.05e-3, Wb3 = 5e-5 M
(base), and the operating point q1 = 16.6, q2 = 0.55, q3 = 15.6 mL/s, h = 14.0 cm, pH = 7.0.
The valve coefficient Cv = 4.59 mL/(s cm^0.607) puts the level at 14.0 cm at that point. The
pH is the root of the titration curve (increasing in pH), solved each step by bisection to
1e-12. Input: the base flow ``q3`` [mL/s]; the buffer flow ``q2`` [mL/s] (measured, not
manipulated); output: ``pH``. The residence time is A h / q = 88 s; the steady gain d pH /
d q3 is 0.3 per mL/s at pH 6.4, 0.5 at pH 7, 2.8 at pH 8 and 0.15 at pH 10: twentyfold over
the problem's box. Tunable parameters for campaigns: ``q1`` [mL/s] (the acid flow),
``Cv_factor``. The control problem: ``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import ExamplePlant

AREA, Z, N_VALVE, CV = 207.0, 11.5, 0.607, 4.59
PK1, PK2 = 6.35, 10.33
#: Reaction invariants (Wa, Wb) [M] of the acid, buffer and base streams.
WA1, WB1, WA2, WB2, WA3, WB3 = 3.0e-3, 0.0, -3.0e-2, 3.0e-2, -3.05e-3, 5.0e-5


def titration(wa: float, wb: float, ph: float) -> float:
    """The titration curve's residual at ``ph`` (zero at the effluent's pH)."""
    return (wa + 10.0 ** (ph - 14.0) - 10.0 ** (-ph)
            + wb * (1.0 + 2.0 * 10.0 ** (ph - PK2)) / (1.0 + 10.0 ** (PK1 - ph)
                                                      + 10.0 ** (ph - PK2)))


def solve_ph(wa: float, wb: float) -> float:
    """The pH of invariants ``wa``, ``wb``: the root of :func:`titration` in [0, 14]."""
    lo, hi = 0.0, 14.0
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        if titration(wa, wb, mid) > 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


class PHNeutralisation(ExamplePlant):
    """pH neutralisation (Henson & Seborg): q3 [mL/s], buffer q2 measured -> pH."""

    SIGNALS = """
        input      q3         mL/s   15.6      base flow (NaOH)
        input      q2         mL/s   0.55      buffer flow (NaHCO3), measured
        output     pH         pH     7.0       effluent pH
        parameter  q1         mL/s   16.6      acid flow (HNO3)
        parameter  Cv_factor  1      1.0       multiplies the outlet valve's coefficient
        state      Wa         mol/L  -4.32e-4  reaction invariant Wa of the effluent
        state      Wb         mol/L  5.28e-4   reaction invariant Wb of the effluent
        state      h          cm     14.0      level
    """
    MAX_SUBSTEP = 1.0

    def rhs(self, x: list[float]) -> list[float]:
        wa, wb, h = x
        flows = ((self.q1, WA1, WB1), (self.q2, WA2, WB2), (self.q3, WA3, WB3))
        volume = AREA * h
        return [sum(q * (a - wa) for q, a, _b in flows) / volume,
                sum(q * (b - wb) for q, _a, b in flows) / volume,
                (self.q1 + self.q2 + self.q3 - self.Cv_factor * CV * (h + Z) ** N_VALVE)
                / AREA]

    def clamp(self, x: list[float]) -> list[float]:
        return [x[0], x[1], max(0.1, x[2])]

    def out(self, x: list[float]) -> dict[str, float]:
        return {"pH": solve_ph(x[0], x[1])}
