"""An SSP file (System Structure and Parameterization 1.0) of a plant FMU and a controller FMU
connected by name: ``cosim export-ssp``.

Each signal the controller exchanges with the plant is the plant variable its problem names
(the controller FMU records it, :func:`cosim.core.fmu_archive.plant_variables`; an FMU
without the record: the variable of the signal's own name): the controller's measured
outputs read the plant's outputs, the plant's inputs read the controller's inputs to apply,
each connection with the linear map between the two variables' units where they differ
(``LinearTransformation``, automatic unit conversion suppressed, so every runner converts
alike). Every other controller input gets a constant value from a parameter set: the
set-points ``ref.<output>`` and the measured disturbances ``dist.<name>``, whose plant
variable (an input or a tunable parameter) gets the same value in its own unit, so plant and
controller see one disturbance. So do the controller's tunable parameters given a value (its
weights, ``offset_filter``); its other outputs (``status``, ``pred.*``, ``target.*``) stay
unconnected. Both FMUs go into the archive's ``resources/``; the default experiment's fixed
step is the controller's sample time (the Open Simulation Platform's annotation, which
libcosim reads), so that libcosim runs the file as it is.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

from cosim.core.atomicio import replacing
from cosim.core.binding import Conversion, UnitError, unit_conversion, unit_definitions
from cosim.core.build import add_member
from cosim.core.errors import CosimError, SimulationFailed
from cosim.core.fmu_archive import plant_variables, read_model_description, why_not_valid
from cosim.core.varmap import variable_unit

__all__ = ["Wiring", "rehearse", "system_structure", "wiring", "write_ssp"]

_NS = ('xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
       'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"')


@dataclass(frozen=True)
class Wiring:
    """How plant and controller connect (module docstring).

    Attributes
    ----------
    links : list of (str, str, Conversion)
        ``("plant.<variable>", "mpc.<name>", c)`` or ``("mpc.<name>", "plant.<variable>",
        c)``: ``c`` maps the controller's value to the plant's (``plant = scale · controller
        + offset``).
    free : list of str
        The controller inputs no plant output feeds (set-points, measured disturbances, the
        operator's ``op.*`` settings).
    disturbances : dict
        ``dist.<name>`` → (the plant's variable, the same :class:`Conversion`).
    plant_vars, controller_vars : dict
        Both FMUs' real variables by name.
    """

    links: list[tuple[str, str, Conversion]]
    free: list[str]
    disturbances: dict[str, tuple[str, Conversion]] = field(default_factory=dict)
    plant_vars: Mapping[str, Any] = field(default_factory=dict)
    controller_vars: Mapping[str, Any] = field(default_factory=dict)

    def plant_values(self, values: Mapping[str, float]) -> dict[str, float]:
        """The plant variables' values of the measured disturbances' ``values`` (by
        ``dist.<name>``, the controller's units), in the plant's units."""
        return {var: conv.scale * float(values[name]) + conv.offset
                for name, (var, conv) in self.disturbances.items() if name in values}


def _real_variables(md: Any) -> dict[str, Any]:
    return {v.name: v for v in md.modelVariables if v.type in ("Real", "Float64")}


def _check_value(option: str, name: str, value: float, var: Any, fmu: Path) -> None:
    """A value the SSP gives variable ``var`` of ``fmu``: finite and inside its declared
    box, else :class:`CosimError` naming the option."""
    why = why_not_valid(var, value)
    if why:
        raise CosimError(f"{option} {name}={value:g}: {why} in {fmu}")


def wiring(plant: Path, controller: Path) -> Wiring:
    """How ``plant`` and ``controller`` connect: each controller signal to the plant variable
    the controller records for it (module docstring), with the unit conversion between them.

    Raises
    ------
    CosimError
        No connection from the plant to the controller or none back (the two FMUs do not
        belong together); a measured disturbance whose plant variable the plant lacks
        (or has as neither an input nor a tunable parameter); units that cannot be related.
    """
    md = read_model_description(plant)
    pv, cv = _real_variables(md), _real_variables(read_model_description(controller))
    named, defs = plant_variables(controller), unit_definitions(md)
    links, free, dist = [], [], {}
    for name, var in cv.items():
        target = named.get(name, name.removeprefix("dist."))
        pvar = pv.get(target)
        if var.causality == "input" and name.startswith("dist."):
            if pvar is None or not (pvar.causality == "input" or (
                    pvar.causality == "parameter" and pvar.variability == "tunable")):
                what = "no such variable" if pvar is None else \
                    f"it as a {pvar.variability} {pvar.causality}"
                raise CosimError(f"{controller}: measured disturbance {name!r} is the plant's "
                                 f"variable {target!r}, and {plant} has {what} (an input or "
                                 "a tunable parameter would get the controller's value)")
            free.append(name)
            dist[name] = (target, _conversion(name, var, pvar, defs, plant))
        elif var.causality == "input":
            if pvar is not None and pvar.causality == "output":
                links.append((f"plant.{target}", f"mpc.{name}",
                              _conversion(name, var, pvar, defs, plant)))
            else:
                free.append(name)
        elif var.causality == "output" and pvar is not None and pvar.causality == "input":
            links.append((f"mpc.{name}", f"plant.{target}",
                          _conversion(name, var, pvar, defs, plant)))
    if not any(a.startswith("mpc.") for a, _, _ in links) or not any(
            a.startswith("plant.") for a, _, _ in links):
        raise CosimError(f"{controller} and {plant}: no input of one is named as an output of "
                         "the other both ways (a controller FMU reads the plant's outputs and "
                         "writes its inputs, by name)")
    return Wiring(links, free, dist, pv, cv)


def _conversion(name: str, cvar: Any, pvar: Any, defs: Mapping[str, Any],
                plant: Path) -> Conversion:
    """The map from the controller variable ``cvar``'s unit to the plant's ``pvar``'s (the
    identity where either declares none)."""
    cu, pu = variable_unit(cvar), variable_unit(pvar)
    if not cu or not pu:
        return Conversion()
    try:
        return unit_conversion(cu, pu, defs)
    except UnitError as exc:
        raise CosimError(f"{plant}: variable {pvar.name!r} cannot take the controller's "
                         f"{name!r}: {exc}") from None


def _connectors(variables: Mapping[str, Any], names: set[str]) -> str:
    out = []
    for name in sorted(names):
        var = variables[name]
        unit = variable_unit(var)
        real = f"<ssc:Real unit={quoteattr(unit)}/>" if unit else "<ssc:Real/>"
        out.append(f"        <ssd:Connector name={quoteattr(name)} "
                   f"kind=\"{var.causality}\">{real}</ssd:Connector>\n")
    return "".join(out)


def _bindings(name: str, values: Mapping[str, float]) -> str:
    """A component's ``ParameterBindings`` of ``values`` (parameter set ``name``)."""
    if not values:
        return ""
    params = "".join(f"                <ssv:Parameter name={quoteattr(n)}><ssv:Real "
                     f"value=\"{float(v)!r}\"/></ssv:Parameter>\n"
                     for n, v in sorted(values.items()))
    return ("        <ssd:ParameterBindings>\n          <ssd:ParameterBinding>\n"
            "            <ssd:ParameterValues>\n"
            f'              <ssv:ParameterSet version="1.0" name="{name}">\n'
            "                <ssv:Parameters>\n" + params + "                </ssv:Parameters>\n"
            "              </ssv:ParameterSet>\n            </ssd:ParameterValues>\n"
            "          </ssd:ParameterBinding>\n        </ssd:ParameterBindings>\n")


def _connection(a: str, b: str, conv: Conversion) -> str:
    ends = (f"<ssd:Connection startElement=\"{a.partition('.')[0]}\" "
            f"startConnector={quoteattr(a.partition('.')[2])} endElement=\"{b.partition('.')[0]}\" "
            f"endConnector={quoteattr(b.partition('.')[2])}")
    if conv.identity:
        return f"      {ends}/>\n"
    # plant = scale * controller + offset; end = factor * start + offset
    factor, offset = ((conv.scale, conv.offset) if a.startswith("mpc.")
                      else (1.0 / conv.scale, -conv.offset / conv.scale))
    return (f'      {ends} suppressUnitConversion="true">\n'
            f'        <ssc:LinearTransformation factor="{factor!r}" offset="{offset!r}"/>\n'
            "      </ssd:Connection>\n")


def _check_values(w: Wiring, plant: Path, controller: Path, setpoints: Mapping[str, float],
                  parameters: Mapping[str, float], step_size: float, stop_time: float) -> None:
    """Every value the SSP sets, and its step and stop time (:func:`system_structure`)."""
    cv = w.controller_vars
    tunable = [n for n, v in cv.items() if v.causality == "parameter"]
    unknown = sorted(set(parameters) - set(tunable))
    if unknown:
        raise CosimError(f"--parameter {unknown[0]}: not a parameter of {controller} "
                         f"(parameters: {', '.join(tunable) or 'none'})")
    for name, value in parameters.items():
        _check_value("--parameter", name, value, cv[name], controller)
    # the operator's settings (op.*, cosim.core.operator) keep their start values unless given
    missing = sorted(n for n in set(w.free) - set(setpoints) if not n.startswith("op."))
    if missing:
        raise CosimError(f"{controller}: input {missing[0]!r} is fed by no plant output: give "
                         f"it a value (--setpoint {missing[0]}=VALUE)")
    unknown = sorted(set(setpoints) - set(w.free))
    if unknown:
        raise CosimError(f"--setpoint {unknown[0]}: not a free input of {controller} "
                         f"(free: {', '.join(w.free)})")
    for name, value in setpoints.items():
        _check_value("--setpoint", name, value, cv[name], controller)
    for var, value in w.plant_values(setpoints).items():
        _check_value("--setpoint", var, value, w.plant_vars[var], plant)
    if not (math.isfinite(step_size) and step_size > 0):
        raise CosimError(f"--step {step_size!r}: expected a positive, finite number of seconds")
    if not (math.isfinite(stop_time) and stop_time >= step_size):
        raise CosimError(f"--stop {stop_time!r}: expected a finite stop time of at least one "
                         f"step ({step_size:g} s)")


def system_structure(plant: Path, controller: Path, setpoints: Mapping[str, float],
                     step_size: float, stop_time: float,
                     parameters: Mapping[str, float] | None = None) -> str:
    """The ``SystemStructure.ssd`` of plant and controller (module docstring); ``setpoints``:
    the values of the controller's free inputs (set-points, measured disturbances);
    ``parameters``: values of its parameters (the others keep their start values)."""
    w = wiring(plant, controller)
    parameters = dict(parameters or {})
    _check_values(w, plant, controller, setpoints, parameters, step_size, stop_time)
    plant_values = w.plant_values(setpoints)
    used = {"plant": set(plant_values), "mpc": set(w.free) | set(parameters)}
    for a, b, _ in w.links:
        for end in (a, b):
            comp, _, name = end.partition(".")
            used[comp].add(name)
    conns = "".join(_connection(a, b, conv) for a, b, conv in w.links)
    return (
        f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription {_NS} '
        'version="1.0" name="ClosedLoop">\n  <ssd:System name="ClosedLoop">\n'
        "    <ssd:Elements>\n"
        f"      <ssd:Component name=\"plant\" source=\"resources/{plant.name}\" "
        'type="application/x-fmu-sharedlibrary">\n        <ssd:Connectors>\n'
        + _connectors(w.plant_vars, used["plant"]) + "        </ssd:Connectors>\n"
        + _bindings("disturbances", plant_values) + "      </ssd:Component>\n"
        f"      <ssd:Component name=\"mpc\" source=\"resources/{controller.name}\" "
        'type="application/x-fmu-sharedlibrary">\n        <ssd:Connectors>\n'
        + _connectors(w.controller_vars, used["mpc"]) + "        </ssd:Connectors>\n"
        + _bindings("setpoints", {**setpoints, **parameters})
        + "      </ssd:Component>\n    </ssd:Elements>\n    <ssd:Connections>\n" + conns
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
    plant_values = wiring(plant, controller).plant_values(setpoints)
    try:
        rehearse_fmus([(IsolatedFmuComponent(plant), plant_values), (ctrl, dict(setpoints))],
                      step_size)
    except SimulationFailed as exc:
        raise CosimError(f"the SSP would not run: {exc}") from None
