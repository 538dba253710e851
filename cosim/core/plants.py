"""Plant kinds: what a run's plant argument names, told apart in one place, opened through one
registry of endpoint schemes and file kinds.

A plant is named by a string: a file whose kind is its suffix (``Plant.fmu``: a plant FMU,
the default), or an endpoint ``scheme:...`` (``opc.tcp://host:port``: a live plant over OPC
UA; ``model:FILE``: the GRU model itself as the plant). :func:`kind_of` tells which;
:func:`open_plant` opens it with the opener its kind registers (``"module:function"``,
imported when a run asks for it, as controllers are: :mod:`cosim.core.registry`), which gives
the plant component, its I/O and its pacer (:mod:`cosim.core.pacing`) and what the summary
says of it (:class:`OpenedPlant`).

A new fieldbus is one module implementing :class:`~cosim.core.pacing.PlantIO` with an opener,
and one line registering its scheme (:func:`register`, or an entry of :data:`SCHEMES`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["FILE_KINDS", "SCHEMES", "OpenedPlant", "PlantContext", "PlantKind", "kind_of",
           "open_plant", "plant_path", "register"]


@dataclass(frozen=True)
class PlantKind:
    """A kind of plant: its ``name`` (a scheme, or a file suffix), its ``opener``
    (``"module:function"``, called with the plant's name and a :class:`PlantContext`) and
    whether it is a process on its own clock (``live``: it takes the live options, is paced
    by the wall clock and is not set by the scenario)."""

    name: str
    opener: str
    live: bool = False
    scheme: bool = True


#: Endpoint schemes (``scheme:...``): a live plant over OPC UA, the GRU model as the plant.
SCHEMES: dict[str, PlantKind] = {
    "opc.tcp": PlantKind("opc.tcp", "cosim.live.plant:open_live", live=True),
    "model": PlantKind("model", "cosim.adapters.plants:open_model"),
}
#: File kinds, by suffix: a plant FMU (FMI 2.0 or 3.0).
FILE_KINDS: dict[str, PlantKind] = {
    ".fmu": PlantKind(".fmu", "cosim.adapters.plants:open_fmu", scheme=False),
}
#: The kind of a run without a plant argument (the project's plant FMU).
DEFAULT_KIND = ".fmu"


def register(kind: PlantKind) -> None:
    """Register a plant kind (a scheme, or a file suffix when ``kind.scheme`` is false)."""
    (SCHEMES if kind.scheme else FILE_KINDS)[kind.name] = kind


@dataclass
class PlantContext:
    """What opening a plant may need, from the run: its scenario, controller and the problem
    the plant is bound to (``None``: a controller of its own signals, bound by ``signals`` or
    ``varmap`` alone), the user's variable map, the FMI interface, isolation and step
    timeout, the seed, the communication step given (``None``: the controller's), the live
    options (``None``: none given) and the notice sink."""

    scenario: Any
    controller: Any
    problem: Any = None
    varmap: Any = None
    interface: str = "cs"
    isolate: bool = False
    step_timeout: float | None = None
    seed: int = 0
    step: float | None = None
    live: Any = None
    signals: Any = None
    on_notice: Any = None


@dataclass
class OpenedPlant:
    """An opened plant: its ``component`` (signals, wiring), its ``io`` and ``pacer`` (``None``:
    the component's own I/O, simulated time) and ``meta``, what the run's summary says of it
    (``plant``, ``fmi_version``, ``interface``; ``live`` for a live one)."""

    component: Any
    io: Any = None
    pacer: Any = None
    meta: dict[str, Any] = field(default_factory=dict)


def plant_path(arg: str | Path | None) -> Path:
    """The plant FMU: ``arg``, or the project's, built when missing or stale.

    Raises
    ------
    CosimError
        ``arg`` is a folder or does not exist; the project's FMU cannot be built here.
    """
    from cosim.core.build import default_plant

    if arg is not None:
        path = Path(arg)
        if path.is_dir():
            raise CosimError(f"{path}: is a folder, not an FMU file (.fmu zip archive)")
        if not path.is_file():
            raise CosimError(f"{path}: plant FMU not found")
        return path
    path = default_plant()
    if not path.is_file():
        raise CosimError(f"{path}: not produced by cosim build-fmu")
    return path


def kind_of(plant: str | Path | None) -> PlantKind:
    """The kind of the plant named ``plant``: a registered scheme (``scheme:...``), else the
    file kind of its suffix, else a plant FMU (``None``: the project's), whose opener says
    what is wrong with a file that is none."""
    if plant is None:
        return FILE_KINDS[DEFAULT_KIND]
    text = str(plant)
    if not isinstance(plant, Path):
        scheme, sep, _ = text.partition(":")
        if sep and scheme in SCHEMES:
            return SCHEMES[scheme]
    return FILE_KINDS.get(Path(text).suffix.lower(), FILE_KINDS[DEFAULT_KIND])


def open_plant(plant: str | Path | None, context: PlantContext) -> OpenedPlant:
    """Open the plant named ``plant`` through its kind's opener (module docstring).

    Raises
    ------
    CosimError
        Bad input (an unknown kind, a plant that does not fit the run): nothing was run.
    """
    kind = kind_of(plant)
    if not kind.live and context.live is not None:
        from cosim.core.errors import ParameterError

        raise ParameterError("live", ": live options need a live plant (opc.tcp://...)")
    module, _, name = kind.opener.partition(":")
    opener = getattr(importlib.import_module(module), name)
    return opener(plant, context)
