"""An SSP file (System Structure and Parameterization 1.0) of a plant FMU and a controller FMU
connected by name: ``cosim export-ssp``.

The controller's inputs named as the plant's outputs read them, the plant's inputs named as
the controller's outputs read those (a controller FMU of ``cosim export-fmu`` and its
problem's plant connect so); every other controller input (the set-points ``ref.<output>``)
gets a constant value from a parameter set, as do the controller's tunable parameters given
a value (its weights, ``offset_filter``), and the controller's other outputs (``status``,
``pred.*``, ``target.*``) stay unconnected. Both FMUs go into the archive's ``resources/``;
the default experiment's fixed step is the controller's sample time (the Open Simulation
Platform's annotation, which libcosim reads), so that libcosim runs the file as it is.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

from cosim.core.atomicio import replacing
from cosim.core.build import add_member
from cosim.core.errors import CosimError, SimulationFailed
from cosim.core.fmu_archive import read_model_description, why_not_valid

__all__ = ["connections", "rehearse", "system_structure", "write_ssp"]

_NS = ('xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
       'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"')


def _real_variables(path: Path) -> dict[str, Any]:
    md = read_model_description(path)
    return {v.name: v for v in md.modelVariables if v.type in ("Real", "Float64")}


def _check_value(option: str, name: str, value: float, var: Any, fmu: Path) -> None:
    """A value the SSP gives variable ``var`` of ``fmu``: finite and inside its declared
    box, else :class:`CosimError` naming the option."""
    why = why_not_valid(var, value)
    if why:
        raise CosimError(f"{option} {name}={value:g}: {why} in {fmu}")


def connections(plant: Path, controller: Path) -> tuple[list[tuple[str, str]], list[str]]:
    """``(connections, free inputs)``: ``(from "plant.x" or "mpc.x", to ...)`` by name, and the
    controller inputs no plant output feeds (its set-points).

    Raises
    ------
    CosimError
        A controller output no plant input takes, or no connection at all: the two FMUs do
        not belong together.
    """
    return _links(_real_variables(plant), _real_variables(controller), plant, controller)


def _links(pv: Mapping[str, Any], cv: Mapping[str, Any], plant: Path, controller: Path
           ) -> tuple[list[tuple[str, str]], list[str]]:
    """:func:`connections` of the plant's and the controller's real variables."""
    links, free = [], []
    for name, var in cv.items():
        if var.causality == "input":
            if name in pv and pv[name].causality == "output":
                links.append((f"plant.{name}", f"mpc.{name}"))
            else:
                free.append(name)
        elif var.causality == "output" and name in pv and pv[name].causality == "input":
            links.append((f"mpc.{name}", f"plant.{name}"))
    if not any(a.startswith("mpc.") for a, _ in links) or not any(
            a.startswith("plant.") for a, _ in links):
        raise CosimError(f"{controller} and {plant}: no input of one is named as an output of "
                         "the other both ways (a controller FMU reads the plant's outputs and "
                         "writes its inputs, by name)")
    return links, free


def _connectors(variables: Mapping[str, Any], names: set[str]) -> str:
    out = []
    for name in sorted(names):
        var = variables[name]
        unit = getattr(var, "unit", None) or getattr(getattr(var, "declaredType", None),
                                                     "unit", None)
        real = f"<ssc:Real unit={quoteattr(unit)}/>" if unit else "<ssc:Real/>"
        out.append(f"        <ssd:Connector name={quoteattr(name)} "
                   f"kind=\"{var.causality}\">{real}</ssd:Connector>\n")
    return "".join(out)


def system_structure(plant: Path, controller: Path, setpoints: Mapping[str, float],
                     step_size: float, stop_time: float,
                     parameters: Mapping[str, float] | None = None) -> str:
    """The ``SystemStructure.ssd`` of plant and controller (module docstring); ``setpoints``:
    the values of the controller's free inputs; ``parameters``: values of its parameters
    (the others keep their start values)."""
    pv, cv = _real_variables(plant), _real_variables(controller)
    links, free = _links(pv, cv, plant, controller)
    parameters = dict(parameters or {})
    tunable = [n for n, v in cv.items() if v.causality == "parameter"]
    unknown = sorted(set(parameters) - set(tunable))
    if unknown:
        raise CosimError(f"--parameter {unknown[0]}: not a parameter of {controller} "
                         f"(parameters: {', '.join(tunable) or 'none'})")
    for name, value in parameters.items():
        _check_value("--parameter", name, value, cv[name], controller)
    missing = sorted(set(free) - set(setpoints))
    if missing:
        raise CosimError(f"{controller}: input {missing[0]!r} is fed by no plant output: give "
                         f"it a value (--setpoint {missing[0]}=VALUE)")
    unknown = sorted(set(setpoints) - set(free))
    if unknown:
        raise CosimError(f"--setpoint {unknown[0]}: not a free input of {controller} "
                         f"(free: {', '.join(free)})")
    for name, value in setpoints.items():
        _check_value("--setpoint", name, value, cv[name], controller)
    if not (math.isfinite(step_size) and step_size > 0):
        raise CosimError(f"--step {step_size!r}: expected a positive, finite number of seconds")
    if not (math.isfinite(stop_time) and stop_time >= step_size):
        raise CosimError(f"--stop {stop_time!r}: expected a finite stop time of at least one "
                         f"step ({step_size:g} s)")
    used = {"plant": set(), "mpc": set(free) | set(parameters)}
    for a, b in links:
        for end in (a, b):
            comp, _, name = end.partition(".")
            used[comp].add(name)
    params = "".join(f"                <ssv:Parameter name={quoteattr(n)}><ssv:Real "
                     f"value=\"{float(v)!r}\"/></ssv:Parameter>\n"
                     for n, v in sorted({**setpoints, **parameters}.items()))
    conns = "".join(
        f"      <ssd:Connection startElement=\"{a.partition('.')[0]}\" "
        f"startConnector={quoteattr(a.partition('.')[2])} endElement=\"{b.partition('.')[0]}\" "
        f"endConnector={quoteattr(b.partition('.')[2])}/>\n" for a, b in links)
    return (
        f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription {_NS} '
        'version="1.0" name="ClosedLoop">\n  <ssd:System name="ClosedLoop">\n'
        "    <ssd:Elements>\n"
        f"      <ssd:Component name=\"plant\" source=\"resources/{plant.name}\" "
        'type="application/x-fmu-sharedlibrary">\n        <ssd:Connectors>\n'
        + _connectors(pv, used["plant"]) + "        </ssd:Connectors>\n      </ssd:Component>\n"
        f"      <ssd:Component name=\"mpc\" source=\"resources/{controller.name}\" "
        'type="application/x-fmu-sharedlibrary">\n        <ssd:Connectors>\n'
        + _connectors(cv, used["mpc"]) + "        </ssd:Connectors>\n"
        "        <ssd:ParameterBindings>\n          <ssd:ParameterBinding>\n"
        "            <ssd:ParameterValues>\n"
        '              <ssv:ParameterSet version="1.0" name="setpoints">\n'
        "                <ssv:Parameters>\n" + params + "                </ssv:Parameters>\n"
        "              </ssv:ParameterSet>\n            </ssd:ParameterValues>\n"
        "          </ssd:ParameterBinding>\n        </ssd:ParameterBindings>\n"
        "      </ssd:Component>\n    </ssd:Elements>\n    <ssd:Connections>\n" + conns
        + "    </ssd:Connections>\n  </ssd:System>\n"
        f'  <ssd:DefaultExperiment startTime="0" stopTime="{float(stop_time)!r}">\n'
        "    <ssd:Annotations>\n"
        '      <ssc:Annotation type="com.opensimulationplatform">\n'
        f'        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="{float(step_size)!r}"/>'
        "</osp:Algorithm>\n      </ssc:Annotation>\n    </ssd:Annotations>\n"
        "  </ssd:DefaultExperiment>\n</ssd:SystemStructureDescription>\n")


def write_ssp(plant: str | Path, controller: str | Path, out: str | Path,
              setpoints: Mapping[str, float], stop_time: float,
              step_size: float | None = None,
              parameters: Mapping[str, float] | None = None, *, check: bool = True) -> Path:
    """Write the SSP archive ``out`` of ``plant`` and ``controller`` (atomically); the step is
    the controller's default experiment step size unless ``step_size``; ``parameters``: values
    of the controller's parameters. Returns ``out``.

    Nothing is written that cannot run: every value is finite and inside its variable's
    declared box, the stop time is at least one step, and (``check``) both FMUs are loaded,
    initialised and stepped once with these values (:func:`rehearse`).

    Raises
    ------
    CosimError
        A value, an FMU or a connection the SSP cannot run with (``out`` is not touched).
    OutputError
        ``out`` cannot be written (an existing file is intact).
    """
    plant, controller, out = Path(plant), Path(controller), Path(out)
    for path in (plant, controller):
        if not path.is_file():
            raise CosimError(f"{path}: FMU not found")
    if plant.name == controller.name:
        raise CosimError(f"{plant} and {controller}: the two FMUs need different file names")
    if step_size is None:
        exp = read_model_description(controller).defaultExperiment
        if exp is None or exp.stepSize is None:
            raise CosimError(f"{controller}: no default experiment step size: give --step")
        step_size = float(exp.stepSize)
    ssd = system_structure(plant, controller, setpoints, step_size, stop_time, parameters)
    if check:
        rehearse(plant, controller, setpoints, step_size, parameters)
    with replacing(out) as part, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
        add_member(zf, "SystemStructure.ssd", ssd.encode())
        for path in (plant, controller):
            add_member(zf, f"resources/{path.name}", path.read_bytes())
    return out


def rehearse(plant: Path, controller: Path, setpoints: Mapping[str, float], step_size: float,
             parameters: Mapping[str, float] | None = None) -> None:
    """Load, initialise and step once both FMUs as the SSP will (the controller with its
    ``parameters`` and ``setpoints``), each in a worker process
    (:func:`cosim.core.isolated.rehearse`).

    Raises
    ------
    CosimError
        Either FMU cannot: what it refused or how it failed, in one line.
    """
    from cosim.core.isolated import IsolatedFmuComponent, IsolatedFmuController
    from cosim.core.isolated import rehearse as rehearse_fmus

    ctrl = IsolatedFmuController(controller, **dict(parameters or {}))
    try:
        rehearse_fmus([(IsolatedFmuComponent(plant), {}), (ctrl, dict(setpoints))], step_size)
    except SimulationFailed as exc:
        raise CosimError(f"the SSP would not run: {exc}") from None
