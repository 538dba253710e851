"""The errors the numerical core raises on purpose, each one line naming the quantity.

The core (:mod:`controllers`) knows nothing of co-simulation or of command lines: its errors
name Python parameters and the paper's quantities (``"horizon N must be >= 1"``,
``"sigma_z ... rounds to 1"``). The ``cosim`` command line maps them onto exit codes: a
:class:`ValueError` subclass is bad input (exit 2), a :class:`RuntimeError` subclass a
computation that failed (exit 1).
"""

from __future__ import annotations

__all__ = ["CertificateError", "ControllersError", "DataError", "DesignError",
           "ModelFileError", "OptionError", "ProblemFileError", "SetpointError", "SolverError",
           "StepInputError", "TrainingError", "UnreachableSetpoint"]


class ControllersError(Exception):
    """Base class of every error the numerical core raises on purpose."""


class ModelFileError(ControllersError, ValueError):
    """A model file that cannot be read or is malformed (names the file and the key)."""


class ProblemFileError(ControllersError, ValueError):
    """A control-problem file (or a problem record) that is malformed or contradicts the
    plant or the model (names the file and the line or key)."""


class DesignError(ControllersError, ValueError):
    """A design argument out of range: horizon, weights, observer gains, ``ê_o,0``."""


class OptionError(DesignError):
    """An option of the robust MPC of the wrong type or range, unknown, or of another law
    (names the option: ``option N=0: ...``)."""


class StepInputError(ControllersError, ValueError):
    """A controller step's input never set or not finite (names the controller and the
    input)."""


class CertificateError(ControllersError, ValueError):
    """The model has no certificate (e.g. its update gate saturates, ``th:stability-bonassi``)."""


class SetpointError(ControllersError, ValueError):
    """A set-point that fails a hypothesis of ``th:feasibility-stability``."""


class UnreachableSetpoint(SetpointError):
    """A set-point the model cannot hold with inputs inside the saturation box."""


class DataError(ControllersError, ValueError):
    """Training or identification data the core cannot use."""


class SolverError(ControllersError, RuntimeError):
    """A numerical method that failed (a linear program, an equilibrium search)."""


class TrainingError(ControllersError, RuntimeError):
    """Training ended without a certified model (``ν ≥ 1``, non-finite weights)."""
