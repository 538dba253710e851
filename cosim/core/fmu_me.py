"""Model Exchange: an FMU's equations integrated between communication points by fmpy's CVode.

A Model Exchange FMU brings its equations and its events, not a solver: :class:`ModelExchange`
integrates its continuous states from one communication point to the next (CVode, the
component's ``rtol``), stops at each time event the FMU announces, and handles state, step
and time events by FMI's event iteration (Event Mode, discrete states updated to
convergence, back to Continuous-Time Mode, the solver restarted). Inputs that are tunable
parameters are set in Event Mode, as FMI asks (:meth:`ModelExchange.in_event_mode`).
:class:`cosim.core.fmu.FmuComponent` uses it with ``interface="me"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

__all__ = ["ModelExchange"]


class _NoInput:
    """fmpy's solver applies inputs through this: the component sets them itself."""

    def apply(self, *args: object, **kwargs: object) -> None:
        return None


class ModelExchange:
    """The Model Exchange interface of an instantiated, initialised FMU (fmpy's ``fmu`` of
    FMI 3 when ``fmi3``), integrated by CVode from ``t0`` (relative tolerance ``rtol``)."""

    def __init__(self, fmu: Any, md: Any, fmi3: bool, t0: float, rtol: float) -> None:
        from fmpy.sundials import CVodeSolver

        self.fmu, self.md, self.fmi3 = fmu, md, fmi3
        self.event_update()
        fmu.enterContinuousTimeMode()
        self.solver = CVodeSolver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators,
            get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
            get_dx=fmu.getContinuousStateDerivatives if fmi3 else fmu.getDerivatives,
            get_z=fmu.getEventIndicators,
            get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime,
            input=_NoInput(), startTime=t0, relativeTolerance=rtol, maxNumSteps=100000)
        self.next_event: float | None = None

    def event_update(self) -> None:
        """Iterate discrete states to convergence (FMU in event/initialisation mode left)."""
        update = self.fmu.updateDiscreteStates if self.fmi3 else self.fmu.newDiscreteStates
        needed = True
        while needed:
            needed, terminate, _, _, defined, next_time = update()
            if terminate:
                raise RuntimeError("the FMU requested termination")
        self.next_event = next_time if defined else None

    def in_event_mode(self, change: Callable[[], None]) -> None:
        """Make ``change`` (set inputs or parameters) in Event Mode, then the event
        iteration and back to Continuous-Time Mode."""
        self.fmu.enterEventMode()
        change()
        self.event_update()
        self.fmu.enterContinuousTimeMode()

    def step(self, t: float, t_end: float, restart: bool) -> None:
        """Integrate from ``t`` to ``t_end``, handling the events on the way; ``restart``:
        the inputs changed since the last step (the solver starts afresh at ``t``)."""
        fmu, solver = self.fmu, self.solver
        if restart:
            solver.reset(t)
        time = t
        while time < t_end and not math.isclose(time, t_end, rel_tol=1e-12, abs_tol=1e-12):
            target = t_end
            if self.next_event is not None and time < self.next_event < t_end:
                target = self.next_event
            state_event, _, time = solver.step(time, target)
            fmu.setTime(time)
            step_event = False
            if self.md.modelExchange.needsCompletedIntegratorStep:
                step_event, terminate = fmu.completedIntegratorStep()
                if terminate:
                    raise RuntimeError("the FMU requested termination")
            time_event = self.next_event is not None and math.isclose(time, self.next_event)
            if state_event or step_event or time_event:
                self.in_event_mode(lambda: None)
                solver.reset(time)
