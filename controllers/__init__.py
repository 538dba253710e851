"""The numerical core: GRU model, δISS certificates, observer, constraint tightening, MPC.

This package knows nothing of FMUs or of co-simulation: it works on arrays in normalised units
and raises its own errors (:mod:`controllers.errors`), and imports nothing of ``cosim`` (an
import contract, ``tests/test_layering.py``). Its co-simulation adapters (the robust MPC,
the PI baseline and the GRU model as a plant) live one layer up, in :mod:`cosim.adapters`.
Only :mod:`controllers.identification.training` needs torch.

The main names, importable from here::

    from controllers import GRUModel, compute_certificate, FHOCP, RobustMPC, GRUObserver

Names are imported on first use (``import controllers`` stays fast).
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "DEFAULT_MODEL",
    "FHOCP",
    "Certificate",
    "ControllersError",
    "FHOCPResult",
    "GRUModel",
    "GRUObserver",
    "MPCOptions",
    "ReferenceGovernor",
    "RobustMPC",
    "choose_gain_scale",
    "compute_certificate",
    "equilibrium",
    "observer_gains_lp",
]

_EXPORTS = {
    "GRUModel": ("controllers.model", "GRUModel"),
    "DEFAULT_MODEL": ("controllers.model", "DEFAULT_MODEL"),
    "Certificate": ("controllers.certification.certificates", "Certificate"),
    "compute_certificate": ("controllers.certification.certificates", "compute_certificate"),
    "choose_gain_scale": ("controllers.certification.gain_design", "choose_gain_scale"),
    "observer_gains_lp": ("controllers.certification.observer_gains", "observer_gains_lp"),
    "equilibrium": ("controllers.equilibrium", "equilibrium"),
    "FHOCP": ("controllers.ocp.fhocp", "FHOCP"),
    "FHOCPResult": ("controllers.ocp.fhocp", "FHOCPResult"),
    "RobustMPC": ("controllers.mpc", "RobustMPC"),
    "MPCOptions": ("controllers.mpc_options", "MPCOptions"),
    "GRUObserver": ("controllers.observer", "GRUObserver"),
    "ReferenceGovernor": ("controllers.laws.paper.governor", "ReferenceGovernor"),
    "ControllersError": ("controllers.errors", "ControllersError"),
}


def __getattr__(name: str) -> Any:
    """Import an exported name on first use (PEP 562)."""
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'controllers' has no attribute {name!r}") from None
    import importlib

    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
