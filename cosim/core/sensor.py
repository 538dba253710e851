"""Measurement perturbations between plant and controller: bias and seeded random noise
(Gaussian with a standard deviation, or uniform in ``[−a, a]``)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from cosim.core.component import Component, Signal

__all__ = ["SensorModel"]


class SensorModel(Component):
    """``y_measured = y + bias + noise``, ``noise ~ N(0, sd²) + U(−a, a)`` drawn each step.

    Parameters
    ----------
    signals : iterable of str
        The measured outputs it passes through (inputs and outputs have the same names).
    seed : int
        Seed of the noise generator (numpy ``default_rng``): the same seed gives the same
        noise sequence.

    Notes
    -----
    Noise is drawn only for signals with a positive standard deviation (or half-width), in the
    order of ``signals`` (the Gaussian draw before the uniform one), so adding noise to one
    signal does not change another's sequence unless both are noisy.
    """

    direct_feedthrough = True

    def __init__(self, signals: Iterable[str], seed: int = 0, name: str = "sensor") -> None:
        self.name = name
        names = tuple(signals)
        self.inputs = tuple(Signal(n) for n in names)
        self.outputs = self.inputs
        self.bias = dict.fromkeys(names, 0.0)
        self.noise = dict.fromkeys(names, 0.0)
        self.uniform = dict.fromkeys(names, 0.0)
        self._rng = np.random.default_rng(seed)
        self._in = dict.fromkeys(names, 0.0)
        self._out = dict.fromkeys(names, 0.0)

    def set_bias(self, signal: str, value: float) -> None:
        """Set the additive bias of one signal (signal units)."""
        self.bias[signal] = float(value)

    def set_noise(self, signal: str, sd: float) -> None:
        """Set the noise standard deviation of one signal (signal units, ≥ 0)."""
        if sd < 0:
            raise ValueError(f"noise standard deviation of {signal} is negative")
        self.noise[signal] = float(sd)

    def set_uniform(self, signal: str, half_width: float) -> None:
        """Set the half-width ``a`` of uniform noise in ``[−a, a]`` (signal units, ≥ 0)."""
        if half_width < 0:
            raise ValueError(f"uniform noise half-width of {signal} is negative")
        self.uniform[signal] = float(half_width)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        """True plant outputs."""
        for k in self._in:
            if k in values:
                self._in[k] = values[k]

    def step(self, t: float, dt: float) -> None:
        """Compute the measured values for ``[t, t + dt)``."""
        rng = self._rng
        for k, y in self._in.items():
            sd, a = self.noise[k], self.uniform[k]
            v = y + self.bias[k] + (rng.normal(0.0, sd) if sd > 0 else 0.0)
            self._out[k] = v + rng.uniform(-a, a) if a > 0 else v

    def get_outputs(self) -> dict[str, float]:
        """Measured values."""
        return dict(self._out)
