"""A controller for the live tests of measured disturbances (``--controller
tests.cosim.live.controllers:AmbientP``): a proportional law on the heater's temperature
with a static feedforward from the measured ambient temperature, so that a run's inputs
show what it measured."""

from __future__ import annotations

from collections.abc import Mapping

from cosim.core.component import Capability, Component, Signal


class AmbientP(Component):
    """``P = Kp (ref.T − T) + Kff (20 − T_in)`` clipped to ``[0, 2000]`` W."""

    name = "ambient-p"
    inputs = (Signal("T", "degC"), Signal("ref.T", "degC"), Signal("dist.T_in", "degC"))
    outputs = (Signal("P", "W"),)
    direct_feedthrough = True
    sample_time = 20.0
    #: it measures a disturbance, whose nominal value it declares
    capabilities = frozenset({Capability.DISTURBANCES})
    disturbance_defaults = {"T_in": 20.0}   # noqa: RUF012 - read-only

    def __init__(self, Kp: float = 100.0, Kff: float = 50.0) -> None:
        self.Kp, self.Kff = float(Kp), float(Kff)
        self._in: dict[str, float] = {}
        self._P = 0.0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        self._in.update(values)

    def step(self, t: float, dt: float) -> None:
        v = self._in
        p = self.Kp * (v["ref.T"] - v["T"]) + self.Kff * (20.0 - v["dist.T_in"])
        self._P = min(max(p, 0.0), 2000.0)

    def get_outputs(self) -> dict[str, float]:
        return {"P": self._P}
