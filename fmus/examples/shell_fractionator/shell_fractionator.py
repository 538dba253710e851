"""The Shell heavy-oil fractionator, its 3 x 3 part (pythonfmu, FMI 2.0 CS), both reflux
duties it does not manipulate measured.

D. M. Prett and M. Morari (eds.), *The Shell Process Control Workshop*, Butterworths, 1987
(the "Shell standard control problem", Prett & Garcia, *Fundamental Process Control*, 1988;
Maciejowski, *Predictive Control with Constraints*, 2002, sec. 9.1): first-order-plus-dead-
time responses in minutes, normalised variables (dimensionless, 0 at the operating point).
The 3 x 3 part of the 7 x 5 model: the top end point ``y1``, the side end point ``y2`` and the
bottom reflux temperature ``y3`` (the workshop's y7) against the top draw ``u1``, the side
draw ``u2`` and the bottoms reflux duty ``u3``, with the intermediate and upper reflux duties
``u4``, ``u5`` (disturbances in the workshop, measured here)::

    G_ij(s) = K_ij exp(-theta_ij s) / (tau_ij s + 1)

         gain K_ij                   tau_ij [min]          theta_ij [min]
         u1   u2   u3   u4   u5      u1  u2  u3  u4  u5    u1  u2  u3  u4  u5
    y1  4.05 1.77 5.88 1.20 1.44     50  60  50  45  40    27  28  27  27  27
    y2  5.39 5.72 6.90 1.52 1.83     50  60  40  25  20    18  14  15  15  15
    y3  4.38 4.42 7.20 1.14 1.26     33  44  19  24  32    20  22   0   0   0

The workshop's uncertainty: each gain is ``K_ij + dK_ij eps_j`` with ``|eps_j| <= 1``, ``dK``
= (2.11, 0.39, 0.59, 0.12, 0.16) on y1, (3.29, 0.57, 0.89, 0.13, 0.13) on y2, (3.11, 0.73,
1.33, 0.18, 0.10) on y3: the tunable parameters ``eps1`` ... ``eps5`` (0: the nominal plant),
drawn per campaign run. Integrated in 60 s substeps (every dead time a whole number of
minutes: exact). The control problem (Ts = 4 min, the workshop's): ``problem.toml`` beside
this file.
"""

from __future__ import annotations

from plant_base import TransferFunctionPlant

#: The workshop's gain uncertainties dK_ij (rows y1, y2, y3; columns u1..u5).
GAIN_UNCERTAINTY = ((2.11, 0.39, 0.59, 0.12, 0.16),
                    (3.29, 0.57, 0.89, 0.13, 0.13),
                    (3.11, 0.73, 1.33, 0.18, 0.10))


class ShellFractionator(TransferFunctionPlant):
    """Shell heavy-oil fractionator (3 x 3 part): u1-u3, u4 and u5 measured -> y1-y3."""

    SIGNALS = """
        input      u1    1  0.0  top draw
        input      u2    1  0.0  side draw
        input      u3    1  0.0  bottoms reflux duty
        input      u4    1  0.0  intermediate reflux duty (measured)
        input      u5    1  0.0  upper reflux duty (measured)
        output     y1    1  0.0  top end point
        output     y2    1  0.0  side end point
        output     y3    1  0.0  bottom reflux temperature (the workshop's y7)
        parameter  eps1  1  0.0  gain uncertainty of u1's channels, in [-1, 1]
        parameter  eps2  1  0.0  gain uncertainty of u2's channels, in [-1, 1]
        parameter  eps3  1  0.0  gain uncertainty of u3's channels, in [-1, 1]
        parameter  eps4  1  0.0  gain uncertainty of u4's channels, in [-1, 1]
        parameter  eps5  1  0.0  gain uncertainty of u5's channels, in [-1, 1]
    """
    GAIN = ((4.05, 1.77, 5.88, 1.20, 1.44),
            (5.39, 5.72, 6.90, 1.52, 1.83),
            (4.38, 4.42, 7.20, 1.14, 1.26))
    TAU = ((50.0, 60.0, 50.0, 45.0, 40.0),
           (50.0, 60.0, 40.0, 25.0, 20.0),
           (33.0, 44.0, 19.0, 24.0, 32.0))
    DEAD = ((27.0, 28.0, 27.0, 27.0, 27.0),
            (18.0, 14.0, 15.0, 15.0, 15.0),
            (20.0, 22.0, 0.0, 0.0, 0.0))
    MAX_SUBSTEP = 60.0

    def gain(self, i: int, j: int) -> float:
        """``K_ij + dK_ij eps_j`` (the workshop's uncertainty)."""
        return self.GAIN[i][j] + GAIN_UNCERTAINTY[i][j] * getattr(self, f"eps{j + 1}")

    def tau(self, i: int, j: int) -> float:
        return self.TAU[i][j] * self.TIME_UNIT
