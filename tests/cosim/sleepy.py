"""Controllers for the fault tests of ``cosim run`` and campaigns (``--controller
tests.cosim.sleepy:<Class>`` from the repository root): the PI baseline made slow, hung from
some time on, with a bug (an internal error where a run names the phase it failed in), or
asking for more than its box."""

from __future__ import annotations

import time

from cosim.adapters.pi import PIController
from cosim.core.component import Capability


class SleepyPI(PIController):
    """The PI baseline that sleeps ``delay`` seconds in every step, and from ``hang_at``
    seconds of simulated time on sleeps ``hang`` seconds (a hung controller)."""

    def __init__(self, delay: float = 0.0, hang_at: float = float("inf"),
                 hang: float = 3600.0) -> None:
        super().__init__()
        self.delay, self.hang_at, self.hang = float(delay), float(hang_at), float(hang)

    def step(self, t: float, dt: float) -> None:
        time.sleep(self.hang if t >= self.hang_at else self.delay)
        super().step(t, dt)


class TimedPI(PIController):
    """The PI baseline with a wall-clock diagnostic (written to ``timings.csv``)."""

    timing_diagnostics = frozenset({"step_ms"})

    def step(self, t: float, dt: float) -> None:
        t0 = time.perf_counter()
        super().step(t, dt)
        self._step_ms = 1e3 * (time.perf_counter() - t0)

    def diagnostics(self) -> dict[str, float]:
        return {**super().diagnostics(), "step_ms": self._step_ms}


class BuggyPI(PIController):
    """The PI baseline with a bug from ``fail_at`` seconds on: ``step`` indexes past the end
    of a list (an internal error of the controller)."""

    def __init__(self, fail_at: float = 0.0) -> None:
        super().__init__()
        self.fail_at = float(fail_at)

    def step(self, t: float, dt: float) -> None:
        if t >= self.fail_at:
            gains: list[float] = []
            gains[len(self.loops)] += 1.0
        super().step(t, dt)


class ForgetfulPI(PIController):
    """The PI baseline that, from ``forget_at`` seconds on, returns no outputs (a bug the
    master meets while it records the step, outside the controller's own step)."""

    def __init__(self, forget_at: float = 0.0) -> None:
        super().__init__()
        self.forget_at = float(forget_at)
        self._t = 0.0

    def step(self, t: float, dt: float) -> None:
        self._t = t
        super().step(t, dt)

    def get_outputs(self) -> dict[str, float]:
        return {} if self._t >= self.forget_at else super().get_outputs()


class ReadOnlyEstimatePI(PIController):
    """The PI baseline declaring a state estimate it cannot start from (campaigns give its
    drawn start to the controllers that declare one: an internal error before the run
    starts)."""

    capabilities = PIController.capabilities | {Capability.ESTIMATE}

    def set_initial_estimate(self, x0: object) -> float:
        raise RuntimeError("initial_estimate is read-only")


class NativePI(PIController):
    """The PI baseline gone wrong in native code from ``fault_at`` seconds on (as a solver or
    a compiled kernel can): ``fault="crash"`` reads address 0 (a segfault), ``fault="hang"``
    spins in the C loop ``hostile_spin`` of ``library`` (``tests/cosim/hostile/spin.c``),
    which no signal handler interrupts."""

    def __init__(self, fault: str = "crash", fault_at: float = 0.0, library: str = "") -> None:
        super().__init__()
        self.fault, self.fault_at, self.library = fault, float(fault_at), library

    def step(self, t: float, dt: float) -> None:
        import ctypes

        if t >= self.fault_at:
            if self.fault == "hang":
                ctypes.CDLL(self.library).hostile_spin()
            else:
                ctypes.string_at(0)
        super().step(t, dt)


class GreedyPI(PIController):
    """The PI baseline that asks for ``factor`` times the box's upper edge (a controller
    that does not respect its input box: a live plant must never receive it)."""

    def __init__(self, factor: float = 2.0) -> None:
        super().__init__()
        self.factor = float(factor)

    def get_outputs(self) -> dict[str, float]:
        return {u: self.factor * v for u, v in super().get_outputs().items()}
