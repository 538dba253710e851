"""The openers of the plant kinds the adapters bring (:mod:`cosim.core.plants`): a plant FMU
bound to the run's control problem, and the GRU model itself as the plant.

A plant FMU is bound to the problem (:func:`cosim.adapters.problems.bind_plant`: names
through ``variable`` keys, units converted, checked before the first step), else to the
signals a controller FMU records, else through the user's ``--map`` alone; it runs in this
process, or in a worker with ``isolate`` (:class:`cosim.core.isolated.IsolatedFmuComponent`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError
from cosim.core.plants import OpenedPlant, PlantContext

__all__ = ["open_fmu", "open_model", "plant_varmap"]


def plant_varmap(path: Path, varmap: Any, problem: Any = None,
                 signals: list[Any] | None = None) -> Any:
    """The variable map binding the plant FMU ``path`` to ``problem`` (the user's ``varmap``
    first: :func:`cosim.adapters.problems.bind_plant`), else to the ``signals`` a controller
    FMU records (:meth:`cosim.core.fmu_controller.FmuController.plant_signals`), else
    ``varmap`` as it is."""
    if problem is not None:
        from cosim.adapters.problems import bind_plant

        return bind_plant(problem, path, varmap)
    if signals:
        from cosim.core.binding import bind
        from cosim.core.fmu_archive import read_model_description

        return bind(signals, read_model_description(path), path, varmap, signals[0].where)
    return varmap


def open_fmu(plant: str | Path | None, ctx: PlantContext) -> OpenedPlant:
    """A plant FMU (``None``: the project's, built when missing or stale), bound to the run
    (module docstring)."""
    from cosim.core.plants import plant_path

    path = plant_path(plant)
    varmap = plant_varmap(path, ctx.varmap, ctx.problem, ctx.signals)
    if ctx.isolate:
        from cosim.core.isolated import IsolatedFmuComponent

        component: Any = IsolatedFmuComponent(path, name="plant", interface=ctx.interface,
                                              varmap=varmap, timeout=ctx.step_timeout)
    else:
        from cosim.core.fmu import FmuComponent

        component = FmuComponent(path, name="plant", interface=ctx.interface, varmap=varmap)
    return OpenedPlant(component, meta={"plant": str(path),
                                        "fmi_version": component.fmi_version,
                                        "interface": ctx.interface})


def open_model(plant: str | Path, ctx: PlantContext) -> OpenedPlant:
    """The GRU model of ``model:FILE`` as the plant (:class:`cosim.adapters.gru_plant.
    GRUPlant`), its noise seeded with the run's seed."""
    from cosim.adapters.gru_plant import GRUPlant

    if ctx.varmap is not None or ctx.isolate or ctx.interface != "cs":
        raise CosimError(f"--plant {plant}: a GRU-model plant takes no --map, --isolate, "
                         "--step-timeout or --interface")
    component = GRUPlant.from_file(str(plant), seed=ctx.seed)
    return OpenedPlant(component, meta={"plant": str(plant),
                                        "fmi_version": component.fmi_version,
                                        "interface": ctx.interface})
