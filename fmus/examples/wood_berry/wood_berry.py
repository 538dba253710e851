"""The Wood-Berry binary distillation column (pythonfmu, FMI 2.0 CS): 2 x 2 with a dead time
on every channel, its feed flow measured.

R. K. Wood and M. W. Berry, "Terminal composition control of a binary distillation column",
*Chemical Engineering Science* 28 (1973) 1707-1717: a pilot methanol-water column, its top
and bottom compositions identified as first-order-plus-dead-time responses to the reflux and
steam flows and to the feed flow (time in minutes; also Seborg, Edgar, Mellichamp & Doyle,
*Process Dynamics and Control*, and MATLAB's Control System Toolbox example)::

    xD(s) =  12.8 e^-s   / (16.7 s + 1) R(s) - 18.9 e^-3s / (21.0 s + 1) S(s)
            + 3.8 e^-8.1s / (14.9 s + 1) F(s)
    xB(s) =  6.6 e^-7s   / (10.9 s + 1) R(s) - 19.4 e^-3s / (14.4 s + 1) S(s)
            + 4.9 e^-3.4s / (13.2 s + 1) F(s)

in deviation variables around the operating point R = 1.95, S = 1.71, F = 2.45 lb/min,
xD = 96.25, xB = 0.50 mol % (methanol). Inputs: the reflux ``R`` and steam ``S`` flows
[lb/min] and the feed flow ``F`` [lb/min] (set by the plant upstream, measured); outputs: the
top and bottom compositions ``xD``, ``xB`` [mol %]. Each channel has its own dead time (1-8.1
min): a :class:`plant_base.TransferFunctionPlant`, integrated in 6 s substeps (every dead time
a whole number of them: exact). The model is linear: far from the operating point it leaves the
physical range (xB < 0), which the problem's boxes keep the loop away from. Tunable
parameters for campaigns: ``gain_factor``, ``tau_factor``. The control problem:
``problem.toml`` beside this file.
"""

from __future__ import annotations

from plant_base import TransferFunctionPlant


class WoodBerry(TransferFunctionPlant):
    """Wood-Berry column: R, S [lb/min], F measured -> xD, xB [mol%]."""

    SIGNALS = """
        input      R            lb/min  1.95   reflux flow
        input      S            lb/min  1.71   steam flow to the reboiler
        input      F            lb/min  2.45   feed flow (measured)
        output     xD           mol%    96.25  top (distillate) methanol composition
        output     xB           mol%    0.50   bottom methanol composition
        parameter  gain_factor  1       1.0    multiplies every channel's gain
        parameter  tau_factor   1       1.0    multiplies every channel's time constant
    """
    #: rows xD, xB; columns R, S, F (Wood & Berry 1973; minutes)
    GAIN = ((12.8, -18.9, 3.8), (6.6, -19.4, 4.9))
    TAU = ((16.7, 21.0, 14.9), (10.9, 14.4, 13.2))
    DEAD = ((1.0, 3.0, 8.1), (7.0, 3.0, 3.4))
    MAX_SUBSTEP = 6.0
