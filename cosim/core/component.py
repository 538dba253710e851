"""The one interface for everything the master steps: plants, controllers, sensors.

Components are systems wired by signal name (python-control style). The master calls, in
order: :meth:`Component.expect_setpoints` (controllers), :meth:`Component.setup`, then per
communication step ``set_inputs`` / ``step`` / ``get_outputs``, and finally
:meth:`Component.terminate`.

Timing convention (zero-order hold, Gauss-Seidel within a step):

* A component with ``direct_feedthrough = False`` (a plant) exposes in ``get_outputs()`` the
  values at the current time ``t``; ``step(t, dt)`` advances it to ``t + dt`` with its inputs
  held constant.
* A component with ``direct_feedthrough = True`` (a sampled controller, a sensor model)
  computes, in ``step(t, dt)``, outputs from the inputs set at ``t``; these outputs are held
  over ``[t, t + dt)``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["Component", "Signal"]


@dataclass(frozen=True)
class Signal:
    """A named scalar signal with its unit (``""`` when dimensionless)."""

    name: str
    unit: str = ""
    description: str = ""


class Component(ABC):
    """Base class of every block the co-simulation master steps.

    Attributes
    ----------
    name : str
        Instance name, used as the prefix of recorded signals.
    inputs, outputs : tuple of Signal
        Declared signals; the master wires them by name.
    direct_feedthrough : bool
        Whether outputs over ``[t, t+dt)`` depend on inputs at ``t`` (controllers, sensors).
    sample_time : float or None
        Natural sample time [s] (a controller's Ts); the master's default communication step.
    bounds : dict of (float, float)
        Box constraints by signal name, for KPIs (violations) and figures; may name signals
        the component does not own (a controller declares the plant outputs it constrains).
    timing_diagnostics : frozenset of str
        Diagnostics that are wall-clock measurements (e.g. ``solve_ms``). The master records
        them apart (``timings.csv``) so that ``results.csv`` stays reproducible byte for byte.
    isolated : bool
        Whether the component runs its steps in a worker process whose every request its
        ``timeout`` attribute bounds (:mod:`cosim.core.isolated`): the master hands such a
        controller the run's step timeout instead of arming ``SIGALRM``.
    """

    name: str = "component"
    inputs: tuple[Signal, ...] = ()
    outputs: tuple[Signal, ...] = ()
    direct_feedthrough: bool = False
    sample_time: float | None = None
    bounds: dict[str, tuple[float, float]] = {}  # noqa: RUF012 - read-only class default
    timing_diagnostics: frozenset[str] = frozenset()
    isolated: bool = False

    def setup(self, t0: float) -> None:  # noqa: B027 - optional hook
        """Prepare for a run starting at ``t0`` (instantiate, initialise)."""

    def expect_setpoints(self, setpoints: list[dict[str, float]]) -> None:  # noqa: B027
        """Before :meth:`setup`: the set-points the run will request, in order (each by
        output name; :meth:`cosim.core.scenario.Scenario.setpoints`), so that a controller can
        design for them (the robust MPC decides there whether it runs certified). Optional;
        ignored by default."""

    @abstractmethod
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set input signals by name (a subset of :attr:`inputs` is allowed)."""

    @abstractmethod
    def step(self, t: float, dt: float) -> None:
        """Advance over ``[t, t + dt)`` (see the module docstring for timing)."""

    @abstractmethod
    def get_outputs(self) -> dict[str, float]:
        """Current output values by name."""

    def diagnostics(self) -> dict[str, float]:
        """Per-step diagnostics to record (solver statistics, estimates); empty by default."""
        return {}

    def summary(self) -> dict:
        """Whole-run statistics for ``summary.json``; empty by default."""
        return {}

    def terminate(self) -> None:  # noqa: B027 - optional hook
        """Release resources. Must be safe to call more than once."""
