"""A mixing tank with three feeds (pythonfmu, FMI 2.0 CS): 3 inputs, 2 outputs.

Level and temperature of a tank of cross-section A fed with hot (``T_hot``), cold
(``T_cold``) and warm (``T_warm``) water, draining freely through its outlet::

    A dh/dt   = Fh + Fc + Fw - Cv sqrt(h)
    A h dT/dt = Fh (T_hot - T) + Fc (T_cold - T) + Fw (T_warm - T)

(flows in m3/s inside). Inputs: ``Fh``, ``Fc``, ``Fw`` [L/s] in [0.3, 1.5]; outputs: the
level ``h`` [m] and the temperature ``T`` [degC]. Three inputs for two outputs: a plant with
more inputs than outputs (one steady state has many input triples). A = 0.25 m2, Cv = 3 L/s
per sqrt(m): the level settles in 80-250 s, the temperature in 40-170 s. Tunable parameters:
``T_hot``, ``T_cold``, ``T_warm`` [degC], ``Cv_factor``. The control problem:
``problem.toml`` beside this file.
"""

from __future__ import annotations

import math

from plant_base import ExamplePlant

AREA, CV = 0.25, 3.0e-3


class MixingTank(ExamplePlant):
    """Mixing tank: hot, cold and warm feeds -> level and temperature."""

    description = "Mixing tank, Fh, Fc, Fw [L/s] -> h [m] and T [degC] (pythonfmu)"
    SIGNALS = """
        input      Fh         L/s   0.9   hot water flow
        input      Fc         L/s   0.9   cold water flow
        input      Fw         L/s   0.9   warm water flow
        output     h          m     0.8   level
        output     T          degC  41.7  temperature
        parameter  T_hot      degC  70.0  hot water temperature
        parameter  T_cold     degC  15.0  cold water temperature
        parameter  T_warm     degC  40.0  warm water temperature
        parameter  Cv_factor  1     1.0   multiplies the outlet coefficient
    """
    MAX_SUBSTEP = 1.0
    SETTLE = 6000.0

    def rhs(self, x: list[float]) -> list[float]:
        h, t = max(x[0], 1e-3), x[1]
        fh, fc, fw = 1e-3 * self.Fh, 1e-3 * self.Fc, 1e-3 * self.Fw
        out = self.Cv_factor * CV * math.sqrt(h)
        return [(fh + fc + fw - out) / AREA,
                (fh * (self.T_hot - t) + fc * (self.T_cold - t) + fw * (self.T_warm - t))
                / (AREA * h)]

    def clamp(self, x: list[float]) -> list[float]:
        return [max(1e-3, x[0]), x[1]]
