"""Controller registry: short names → ``"module:Class"``; a ``module:Class`` string also works,
and so does a controller file (``*.json``, :mod:`cosim.core.controller_file`: a controller's
name and options recorded by a run) and a controller FMU (``*.fmu``, :mod:`cosim.core.
fmu_controller`, run in a worker process of its own: :mod:`cosim.core.isolated`).

Controllers are :class:`~cosim.core.component.Component` classes constructible without arguments.
"""

from __future__ import annotations

import importlib
import inspect
import json
from collections.abc import Mapping, Sequence
from typing import Any

from cosim.core.component import Component
from cosim.core.errors import CosimError

__all__ = ["CONTROLLERS", "DEFAULT", "FMU_CONTROLLER", "create", "expand", "parse_options",
           "resolve"]

#: Built-in controllers.
CONTROLLERS: dict[str, str] = {
    "pi": "cosim.adapters.pi:PIController",
    "robust-mpc": "cosim.adapters.robust_mpc:RobustMPCController",
}

#: The component of a controller FMU (``--controller Controller.fmu``): native code, run in a
#: worker process that a crash cannot take down and a timeout can kill.
FMU_CONTROLLER = "cosim.core.isolated:IsolatedFmuController"
#: The controller ``cosim run`` uses when none is named.
DEFAULT = "robust-mpc"


def expand(name: str, options: Mapping[str, Any] | None = None
           ) -> tuple[str, dict[str, Any]]:
    """``(name, options)`` with a controller file read: its controller and its options,
    ``options`` given here taking precedence; a registry name or ``module:Class`` as
    given."""
    from cosim.core import controller_file

    if name.lower().endswith(".fmu"):   # a controller FMU (cosim export-fmu)
        return FMU_CONTROLLER, {"path": name, **dict(options or {})}
    if not controller_file.is_controller_file(name):
        return name, dict(options or {})
    inner, recorded = controller_file.load(name)
    return inner, {**recorded, **dict(options or {})}


def resolve(name: str) -> type[Component]:
    """The controller class for a registry name, a ``module:Class`` string or a controller
    file.

    Raises
    ------
    CosimError
        Unknown name, module not importable, class missing or not a Component; a bad
        controller file.
    """
    name, _ = expand(name)
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
    except Exception as exc:  # the module itself fails to import: name it, keep the cause
        why = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise CosimError(f"controller '{name}': importing module '{module_name}' failed: "
                         f"{why}") from exc
    cls = getattr(module, cls_name, None)
    if not isinstance(cls, type) or not issubclass(cls, Component):
        raise CosimError(f"controller '{name}': '{spec}' is not a Component class")
    return cls


def parse_options(items: Sequence[str]) -> dict[str, Any]:
    """Parse ``KEY=VALUE`` strings; a value is read as JSON when it parses, else as text.

    ``setpoint_rate=0.02`` gives a float, ``offset_free=true`` a bool, ``R=[[0.02,0],[0,0.02]]``
    a nested list, ``model=my.json`` the string ``"my.json"``. A key is an identifier, or
    identifiers joined by dots (a controller FMU's parameter: ``R.qa=0.05``).
    """
    options: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not all(part.isidentifier() for part in key.split(".")):
            raise CosimError(f"controller option '{item}': expected KEY=VALUE")
        try:
            options[key] = json.loads(text)
        except json.JSONDecodeError:
            options[key] = text
        except (RecursionError, ValueError) as exc:
            why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
            raise CosimError(f"controller option '{key}': invalid JSON value ({why})") from None
    return options


def create(name: str, options: Mapping[str, Any] | None = None) -> Component:
    """Instantiate a controller by name (or controller file, :func:`expand`), with keyword
    ``options`` for its constructor."""
    name, options = expand(name, options)
    cls = resolve(name)
    params = inspect.signature(cls).parameters
    declared = getattr(cls, "OPTIONS", None)   # a component taking **options names them
    if declared is not None or not any(p.kind is inspect.Parameter.VAR_KEYWORD
                                       for p in params.values()):
        names = list(declared) if declared is not None else [k for k in params if k != "self"]
        for key in options:
            if key not in names:
                raise CosimError(f"controller '{name}' has no option '{key}' (options: "
                                 f"{', '.join(names) or 'none'})")
    try:
        return cls(**options)
    except CosimError:
        raise
    except Exception as exc:
        msg = " ".join(str(exc).split())  # one line (casadi's messages span several)
        # chained: the message is the one line users see, the cause keeps the traceback of
        # what is likely a bug (a campaign writes it to the run's traceback.txt)
        raise CosimError(f"controller '{name}': cannot create {cls.__name__}: "
                         f"{type(exc).__name__}: {msg}") from exc
