"""Controller registry: short names → ``"module:Class"``; a ``module:Class`` string also works.

Controllers are :class:`~cosim.component.Component` classes constructible without arguments.
"""

from __future__ import annotations

import importlib

from cosim.component import Component
from cosim.errors import CosimError

#: Built-in controllers.
CONTROLLERS: dict[str, str] = {
    "pi": "controllers.pi:PIController",
    "robust-mpc": "controllers.component:RobustMPCController",
}

#: The controller ``cosim run`` uses when none is named.
DEFAULT = "robust-mpc"


def resolve(name: str) -> type[Component]:
    """The controller class for a registry name or a ``module:Class`` string.

    Raises
    ------
    CosimError
        Unknown name, module not importable, class missing or not a Component.
    """
    spec = CONTROLLERS.get(name, name)
    if ":" not in spec:
        raise CosimError(f"unknown controller '{name}' (known: {', '.join(CONTROLLERS)}; "
                         "or give module:Class)")
    module_name, _, cls_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        hint = "; try --controller pi" if name != "pi" else ""
        raise CosimError(f"controller '{name}': cannot import module '{module_name}' "
                         f"({exc}){hint}") from None
    cls = getattr(module, cls_name, None)
    if not isinstance(cls, type) or not issubclass(cls, Component):
        raise CosimError(f"controller '{name}': '{spec}' is not a Component class")
    return cls


def create(name: str) -> Component:
    """Instantiate a controller by name (no arguments)."""
    cls = resolve(name)
    try:
        return cls()
    except CosimError:
        raise
    except Exception as exc:
        raise CosimError(f"controller '{name}': cannot create {cls.__name__}: "
                         f"{type(exc).__name__}: {exc}") from None
