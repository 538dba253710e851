"""Build a controller FMU (FMI 2.0 or 3.0 Co-Simulation) from the C source of a controller step.

The controller FMU is laid out as the plant FMUs are (:mod:`cosim.core.build`, the Modelica
Reference-FMUs' way): one model source for every exported controller
(``fmus/controller/model.c``, the FMI variables of a controller step), the FMI glue every C
model shares (``fmus/glue/``), and two generated files: ``controller_step.c`` (the step itself,
:mod:`controllers.kernel.controller_source`, handed in as text: this module knows no
controller) and ``controller_names.h`` (names, numbers, start values and sample time, from a
:class:`ControllerInterface`); the step's numbers are data, ``resources/controller.dat``,
read at instantiation. :func:`build_controller_fmu` compiles the sources with gcc (once per
source: the binary is cached, so a design of the same dimensions and signals, such as a
retrained model, needs no compiler) and zips a source-and-binary FMU whose
``modelDescription.xml`` declares every variable with its unit (``UnitDefinitions`` with SI
base units where pint knows the unit), box and description, the default experiment (the
controller's sample time), the plant variable each signal reads or writes (an annotation,
read by :func:`cosim.core.fmu_archive.plant_variables`: what ``cosim export-ssp`` connects
and ``cosim run`` binds) and no FMU state (the solver's memory is the instance's own). The
archive is reproducible (fixed time stamps) and written atomically.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from cosim.core.atomicio import replacing, write_bytes
from cosim.core.build import (
    GLUE_DIR,
    PACKAGE_DIR,
    add_member,
    cache_dir,
    check_platform,
    compiler,
    compiler_version,
    fmi_headers_dir,
    run_compiler,
)
from cosim.core.errors import CosimError
from cosim.core.fmu_archive import PLANT_ANNOTATION

__all__ = ["CONTROLLER_DIR", "ControllerInterface", "Parameter", "Port", "build_controller_fmu",
           "check_interface", "model_description", "names_header"]

#: The controller model's source (package data of :mod:`fmus`).
CONTROLLER_DIR = PACKAGE_DIR / "controller"
#: The step's numbers in the FMU's ``resources/`` (``fmus/controller/model.h`` CTL_DATA_FILE).
DATA_FILE = "controller.dat"
#: The diagnostic outputs after the inputs to apply (``fmus/controller/model.h``).
DIAGNOSTICS = (("status", "solver status: 0 optimal, 1 infeasible at the estimate, "
                "2 infeasible, 3 iteration limit, 4 answer check failed, 5 other"),
               ("fallback", "1: the shifted candidate was applied (the solve was not used)"),
               ("iterations", "SQP iterations of the step"))
CFLAGS = ("-std=gnu99", "-O3", "-fPIC", "-shared", "-pthread", "-fvisibility=hidden", "-DEXPORT=",
          "-Wall", "-Wextra", "-Werror", "-Wno-aggressive-loop-optimizations")


@dataclass(frozen=True)
class Port:
    """One signal of the controller: name, unit, box, description and the plant FMU's
    variable it is (``variable``; empty: the variable of the signal's own name)."""

    name: str
    unit: str
    low: float
    high: float
    description: str = ""
    variable: str = ""


@dataclass(frozen=True)
class Parameter(Port):
    """A tunable parameter of the controller step: a :class:`Port` with its start value."""

    start: float = 0.0


@dataclass(frozen=True)
class ControllerInterface:
    """What the FMU declares besides the step: its identifier (a C identifier, the binary's
    name), instantiation token, description, sample time, the measured outputs (the FMU's
    inputs, with set-points ``ref.<name>``), the measured disturbances (inputs
    ``dist.<name>``, as the Python controller's), the inputs to apply (its outputs) and the
    tunable parameters, in ``fmus/controller/model.h``'s order."""

    identifier: str
    token: str
    description: str
    sample_time: float
    measured: tuple[Port, ...]
    applied: tuple[Port, ...]
    parameters: tuple[Parameter, ...] = ()
    generation_tool: str = "gru-mpc-cosim (cosim export-fmu)"
    disturbances: tuple[Port, ...] = ()
    #: the operator's settings (inputs ``op.*``, :mod:`controllers.operator`), their start
    #: values the defaults (``Parameter.start``)
    operator: tuple[Parameter, ...] = ()

    def variables(self) -> list[tuple[str, str, str, str, Port | Parameter | None, str]]:
        """``(name, causality, variability, unit, port, description)`` in value-reference
        order from 1 (``fmus/controller/model.h``)."""
        out = [(p.name, "input", "continuous", p.unit, p, p.description or f"measured {p.name}")
               for p in self.measured]
        out += [(f"ref.{p.name}", "input", "continuous", p.unit, p, f"set-point of {p.name}")
                for p in self.measured]
        out += [(f"dist.{p.name}", "input", "continuous", p.unit, p,
                 p.description or f"measured disturbance {p.name}") for p in self.disturbances]
        out += [(p.name, "input", "discrete", p.unit, p, p.description) for p in self.operator]
        out += [(p.name, "output", "discrete", p.unit, p, p.description or f"input {p.name}")
                for p in self.applied]
        out += [(name, "output", "discrete", "1", None, text) for name, text in DIAGNOSTICS]
        out += [(f"pred.{p.name}", "output", "discrete", p.unit, None,
                 f"{p.name} the model predicts at the next sample") for p in self.measured]
        out += [(f"target.{p.name}", "output", "discrete", p.unit, None,
                 f"steady {p.name} the controller steers the model to (the paper's law: its "
                 "governed set-point; the tracking law: the artificial steady state's)")
                for p in self.measured]
        out += [(f"computed.{p.name}", "output", "discrete", p.unit, None,
                 f"{p.name} the controller computed (in manual: what it would have written)")
                for p in self.applied]
        out += [("op.refused", "output", "discrete", "1", None,
                 "operator settings refused so far (each kept as it was; the log says why)")]
        out += [(q.name, "parameter", "tunable", q.unit, q, q.description)
                for q in self.parameters]
        return out

    def plant_variables(self) -> dict[str, str]:
        """The plant FMU's variable of each signal the controller exchanges with the plant,
        by the controller's variable name (a measured output, an input to apply, a measured
        disturbance's ``dist.<name>``)."""
        ports = [(p.name, p) for p in (*self.measured, *self.applied)]
        ports += [(f"dist.{p.name}", p) for p in self.disturbances]
        return {name: p.variable or p.name for name, p in ports}


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def names_header(iface: ControllerInterface) -> str:
    """``controller_names.h``: the generated half of ``fmus/controller/model.h`` (not the
    identifier: the binary is the same under any name)."""
    names = ["time", *(v[0] for v in iface.variables())]
    starts = [0.5 * (p.low + p.high) for p in iface.measured]
    d_starts = [0.5 * (p.low + p.high) for p in iface.disturbances] or [0.0]
    return (
        "/* generated by cosim.core.controller_fmu; do not edit */\n"
        f"#define INSTANTIATION_TOKEN {_c_string(iface.token)}\n"
        f"#define CTL_NY {len(iface.measured)}\n#define CTL_NU {len(iface.applied)}\n"
        f"#define CTL_ND {len(iface.disturbances)}\n"
        f"#define CTL_NOP {len(iface.operator)}\n"
        f"#define CTL_NPARAM {len(iface.parameters)}\n"
        f"#define CTL_TS ({float(iface.sample_time)!r})\n"
        f"static const char *const CTL_NAMES[] = {{{', '.join(map(_c_string, names))}}};\n"
        f"static const double CTL_Y_START[] = {{{', '.join(repr(v) for v in starts)}}};\n"
        f"static const double CTL_D_START[] = {{{', '.join(repr(v) for v in d_starts)}}};\n")


def _base_unit(unit: str) -> str | None:
    """The ``<BaseUnit .../>`` attributes of ``unit`` (SI exponents, factor, offset), ``None``
    when pint does not know it."""
    from cosim.core.binding import si_base_unit

    base = si_base_unit(unit) if unit.strip() not in ("", "1") else {}
    if base is None:
        return None
    return "".join(f' {k}="{int(v) if k not in ("factor", "offset") else v!r}"'
                   for k, v in base.items())


def _units(iface: ControllerInterface) -> str:
    used = sorted({v[3] for v in iface.variables()} | {"s", "1"})
    lines = []
    for unit in used:
        base = _base_unit(unit)
        inner = f"<BaseUnit{base}/>" if base is not None else ""
        lines.append(f"    <Unit name={quoteattr(unit)}>{inner}</Unit>")
    return "  <UnitDefinitions>\n" + "\n".join(lines) + "\n  </UnitDefinitions>\n"


def _attrs(port: Port | Parameter | None, causality: str, unit: str) -> str:
    """A variable's unit, box and start attributes."""
    out = [f"unit={quoteattr(unit)}"]
    if port is not None:
        out.append(f'min="{float(port.low)!r}"')
        if math.isfinite(port.high):   # no upper bound (a weight): no max
            out.append(f'max="{float(port.high)!r}"')
        if isinstance(port, Parameter):
            start = float(port.start)
            out.append(f'start="{"NaN" if math.isnan(start) else repr(start)}"')
        elif causality == "input":
            out.append(f'start="{0.5 * (port.low + port.high)!r}"')
    return " ".join(out)


#: The log categories of the FMU's messages (``fmus/glue/instance.c`` logs under them).
_LOG_CATEGORIES = (
    "  <LogCategories>\n"
    '    <Category name="logStatusError" description="Errors: refused calls and failed '
    'steps"/>\n'
    '    <Category name="logStatusWarning" description="Warnings: non-finite '
    'measurements, an unreachable first output"/>\n'
    '    <Category name="logEvents" description="Events"/>\n  </LogCategories>\n')


def model_description(iface: ControllerInterface, fmi_version: int) -> str:
    """The ``modelDescription.xml`` of the controller FMU for FMI ``fmi_version`` (2 or 3)."""
    fmi3 = fmi_version == 3
    experiment = f'  <DefaultExperiment startTime="0" stepSize="{float(iface.sample_time)!r}"/>\n'
    vendor = ("" if fmi3 else "  <VendorAnnotations>\n"
              f"    <Tool name=\"{PLANT_ANNOTATION}\">\n" + _plant_lines(iface, "      ")
              + "    </Tool>\n  </VendorAnnotations>\n\n")
    variables, outputs = _model_variables(iface, fmi3)
    body = [_head(iface, fmi3), _co_simulation(iface.identifier, fmi3), "\n", _units(iface),
            "\n", _LOG_CATEGORIES, "\n", experiment, "\n", vendor, *variables,
            _model_structure(outputs, fmi3)]
    if fmi3:
        body.append(f"  <Annotations>\n    <Annotation type=\"{PLANT_ANNOTATION}\">\n"
                    + _plant_lines(iface, "      ") + "    </Annotation>\n  </Annotations>\n")
    body.append("</fmiModelDescription>\n")
    return "".join(body)


def _head(iface: ControllerInterface, fmi3: bool) -> str:
    """The XML declaration and the ``fmiModelDescription`` element's attributes."""
    q = quoteattr
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription\n'
            f'  fmiVersion="{"3.0" if fmi3 else "2.0"}"\n  modelName={q(iface.identifier)}\n'
            + (f"  instantiationToken={q(iface.token)}\n" if fmi3 else f"  guid={q(iface.token)}\n")
            + f"  description={q(iface.description)}\n"
            f"  generationTool={q(iface.generation_tool)}\n"
            '  variableNamingConvention="structured"'
            + ("" if fmi3 else '\n  numberOfEventIndicators="0"') + ">\n\n")


def _co_simulation(ident: str, fmi3: bool) -> str:
    """The ``CoSimulation`` element: no FMU state; FMI 2's lists the source files."""
    state = "FMUState" if fmi3 else "FMUstate"
    return (f'  <CoSimulation modelIdentifier={quoteattr(ident)} '
            f'canHandleVariableCommunicationStepSize="true" canGetAndSet{state}="false" '
            f'canSerialize{state}="false"'
            + ("/>\n" if fmi3 else ">\n    <SourceFiles>\n"
               + "".join(f'      <File name="{f}"/>\n' for f in ("model.c", "controller_step.c",
                                                                  "instance.c", "fmi2.c"))
               + "    </SourceFiles>\n  </CoSimulation>\n"))


def _model_variables(iface: ControllerInterface, fmi3: bool) -> tuple[list[str], list[int]]:
    """The ``ModelVariables`` element's lines (FMI 3 declares the time too), and the value
    references of the outputs (FMI 2 indexes the variables from 1 in this order: the same)."""
    q = quoteattr
    lines = ["  <ModelVariables>\n"]
    if fmi3:
        lines.append('    <Float64 name="time" valueReference="0" causality="independent" '
                     'variability="continuous" description="Simulation time" unit="s"/>\n')
    outputs = []
    for vr, (name, causality, variability, unit, port, text) in enumerate(
            iface.variables(), start=1):
        initial = {"output": ' initial="calculated"', "parameter": ' initial="exact"'}.get(
            causality, "")
        attrs = _attrs(port, causality, unit)
        common = (f"name={q(name)} valueReference=\"{vr}\" causality=\"{causality}\" "
                  f"variability=\"{variability}\"{initial} description={q(text)}")
        if fmi3:
            lines.append(f"    <Float64 {common} {attrs}/>\n")
        else:
            lines.append(f"    <ScalarVariable {common}>\n      <Real {attrs}/>\n"
                         "    </ScalarVariable>\n")
        if causality == "output":
            outputs.append(vr)
    lines.append("  </ModelVariables>\n\n")
    return lines, outputs


def _model_structure(outputs: list[int], fmi3: bool) -> str:
    """The ``ModelStructure`` element: every output is an initial unknown too."""
    body = ["  <ModelStructure>\n"]
    if fmi3:
        body += [f'    <Output valueReference="{vr}"/>\n' for vr in outputs]
        body += [f'    <InitialUnknown valueReference="{vr}"/>\n' for vr in outputs]
    else:
        unknowns = "".join(f'      <Unknown index="{i}"/>\n' for i in outputs)
        body.append("    <Outputs>\n" + unknowns + "    </Outputs>\n")
        body.append("    <InitialUnknowns>\n" + unknowns + "    </InitialUnknowns>\n")
    body.append("  </ModelStructure>\n\n")
    return "".join(body)


def _plant_lines(iface: ControllerInterface, indent: str) -> str:
    """The annotation's one element (FMI 2 allows one per tool): the plant variables."""
    return (f"{indent}<PlantVariables>\n"
            + "".join(f"{indent}  <Variable name={quoteattr(name)} plant={quoteattr(var)}/>\n"
                      for name, var in iface.plant_variables().items())
            + f"{indent}</PlantVariables>\n")


def _binary(files: dict[str, bytes], glue: str, flags: Sequence[str]) -> bytes:
    """The FMU's binary from its sources ``files`` (FMI glue ``glue``), compiled once per
    source, compiler and flags (cached in :func:`cosim.core.build.cache_dir`)."""
    cc = compiler()
    digest = hashlib.sha256("\0".join((*CFLAGS, *flags, compiler_version(cc))).encode())
    for name in sorted(files):
        digest.update(b"\0" + name.encode() + b"\0" + files[name])
    cached = cache_dir() / "controllers" / f"{digest.hexdigest()[:20]}.so"
    if cached.is_file():
        return cached.read_bytes()
    with tempfile.TemporaryDirectory(prefix="cosim-export-") as tmp:
        folder = Path(tmp)
        for name, data in files.items():
            (folder / name).write_bytes(data)
        out = folder / "binary.so"
        sources = [folder / name for name in ("model.c", "controller_step.c", "instance.c", glue)]
        run_compiler([cc, *CFLAGS, *flags, f"-I{fmi_headers_dir()}", f"-I{folder}", "-o",
                      str(out), *map(str, sources), "-Wl,--no-undefined", "-lm"],
                     "the controller FMU")
        binary = out.read_bytes()
    try:
        cached.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(cached, binary)
    except OSError:
        pass   # a read-only cache: compiled again next time
    return binary


def build_controller_fmu(iface: ControllerInterface, step_source: str, data: bytes,
                         out: str | Path, *, fmi_version: int = 3,
                         flags: Sequence[str] = ()) -> Path:
    """Compile ``step_source`` (``controller_step.c``: the controller step with the symbol
    prefix ``mpc_``) with the controller model and the FMI glue, and zip it with the step's
    numbers ``data`` (``resources/controller.dat``) into the FMU ``out`` (FMI
    ``fmi_version``; ``flags``: extra compiler flags, the step's build-time variant);
    returns ``out``. The binary depends on the sources only: it is compiled once and reused
    for every ``data``. An existing ``out`` is replaced only when the new FMU is complete and
    runs: its numbers are checked (:func:`check_interface`), and it is instantiated and
    stepped once in a worker process before it takes the place of ``out``.

    Raises
    ------
    CosimError
        No C compiler, another platform than x86-64 Linux, a failed compilation, numbers
        that cannot run, or an FMU that does not.
    OutputError
        ``out`` cannot be written (an existing file is intact).
    """
    if fmi_version not in (2, 3):
        raise CosimError(f"--fmi {fmi_version}: expected 2 or 3")
    if not iface.identifier.isidentifier():
        raise CosimError(f"FMU name {iface.identifier!r} is not a C identifier (letters, "
                         "digits and _; not starting with a digit)")
    check_platform()
    check_interface(iface)
    out = Path(out)
    glue = f"fmi{fmi_version}.c"
    platform_dir = "x86_64-linux" if fmi_version == 3 else "linux64"
    files: dict[str, bytes] = {"controller_step.c": step_source.encode(),
                               "controller_names.h": names_header(iface).encode()}
    for name in ("model.h", "model.c"):
        files[name] = (CONTROLLER_DIR / name).read_bytes()
    for name in ("instance.h", "instance.c", glue):
        files[name] = (GLUE_DIR / name).read_bytes()
    binary = _binary(files, glue, flags)
    with replacing(out) as part:
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            add_member(zf, "modelDescription.xml",
                       model_description(iface, fmi_version).encode())
            add_member(zf, f"binaries/{platform_dir}/{iface.identifier}.so", binary,
                       executable=True)
            add_member(zf, f"resources/{DATA_FILE}", data)
            for name, source in sorted(files.items()):
                add_member(zf, f"sources/{name}", source)
            if fmi_version == 3:
                add_member(zf, "sources/buildDescription.xml", _build_description(
                    iface.identifier, flags).encode())
        _rehearse(part, out, iface.sample_time)
    return out


def _rehearse(part: Path, out: Path, sample_time: float) -> None:
    """Instantiate the FMU ``part`` (to become ``out``) and run one controller step at its
    start values, in a worker process: an FMU that cannot run is never written."""
    from cosim.core.isolated import IsolatedFmuController, rehearse

    try:
        rehearse([(IsolatedFmuController(part), {})], sample_time)
    except CosimError as exc:
        why = str(exc).replace(str(part), out.name).replace(part.name, out.name)
        raise CosimError(f"{out}: the exported FMU does not run, so it is not written: "
                         f"{why}") from None


def check_interface(iface: ControllerInterface) -> None:
    """Raise :class:`CosimError` unless every number the modelDescription declares can run:
    a positive, finite sample time; each signal's box ``low <= high`` with a finite
    ``low``; each parameter's finite start inside its box."""
    if not (math.isfinite(iface.sample_time) and iface.sample_time > 0):
        raise CosimError(f"sample time {iface.sample_time!r}: expected a positive, finite "
                         "number of seconds")
    for port in (*iface.measured, *iface.disturbances, *iface.applied, *iface.parameters):
        if not (math.isfinite(port.low) and port.low <= port.high) or math.isnan(port.high):
            raise CosimError(f"{port.name}: its box [{port.low!r}, {port.high!r}] is not "
                             "one (a finite low, a high not below it)")
        if isinstance(port, Parameter) and not (
                math.isfinite(port.start) and port.low <= port.start <= port.high):
            raise CosimError(f"parameter {port.name}: its start value {port.start!r} is "
                             f"not inside its box [{port.low!r}, {port.high!r}]")


def _build_description(identifier: str, flags: Sequence[str]) -> str:
    """FMI 3's ``sources/buildDescription.xml``: the sources and the defines to build."""
    defines = "".join(
        f'      <PreprocessorDefinition name="{f[2:].split("=")[0]}"'
        + (f' value="{f.split("=", 1)[1]}"' if "=" in f else "") + "/>\n"
        for f in ("-DEXPORT=", *flags) if f.startswith("-D"))
    files = "".join(f'      <SourceFile name="{n}"/>\n'
                    for n in ("model.c", "controller_step.c", "instance.c", "fmi3.c"))
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{identifier}">\n'
            '    <SourceFileSet language="C99">\n' + files + defines
            + "    </SourceFileSet>\n  </BuildConfiguration>\n</fmiBuildDescription>\n")
