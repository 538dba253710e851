"""Hostile FMUs built from C sources in this folder (``model.c``, on the project's shared FMI
glue): native code that behaves until ``fault_time`` and then does what ``fault`` says.

:func:`build` compiles one of two roles, both FMI 2.0 Co-Simulation:

* ``"controller"``: ``HostileController.fmu``, the interface of the exported four-tank
  controller (inputs ``h1``, ``h2``, ``ref.h1``, ``ref.h2``; outputs ``qa``, ``qb`` and the
  diagnostics ``status``, ``fallback``, ``iterations``; sample time 25 s), an integral law;
  its parameters ``fault`` and ``fault_time`` are options of a run
  (``--option fault=2 --option fault_time=50``).
* ``"plant"``: ``HostilePlant.fmu``, the four-tank's signals (inputs ``qa``, ``qb``; outputs
  ``h1``, ``h2``), two first-order tanks; ``fault`` and ``fault_time`` are scenario columns
  (``plant.fault``, ``plant.fault_time``).

:data:`FAULTS` names the faults: ``hang`` (a busy loop), ``segfault`` (a write through a null
pointer), ``abort`` (after a line on standard error), ``exit`` (``exit(0)``), ``flood``
(1 MiB on standard output and 200 logged warnings every step, then healthy), ``signal``
(SIGTERM to its whole process group).

:func:`build_spin` compiles ``spin.c``, a C loop that never returns, for a Python controller
stuck in native code (``tests/cosim/sleepy.py`` ``NativePI``).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The faults, by the value of the parameter ``fault`` (``model.h`` FAULT_*).
FAULTS = {"none": 0, "hang": 1, "segfault": 2, "abort": 3, "exit": 4, "flood": 5, "signal": 6}
#: The file name and identifier of each role.
IDENTIFIERS = {"controller": "HostileController", "plant": "HostilePlant"}

_HEAD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{ident}"
  guid="{{6b1f9a52-3c0e-4d7a-8f21-5e9d0c4b7a13}}"
  description="a hostile FMU (tests/cosim/hostile)" numberOfEventIndicators="0"
  variableNamingConvention="structured">
  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"/>
  <UnitDefinitions><Unit name="m"/><Unit name="m3/s"/></UnitDefinitions>
  <DefaultExperiment startTime="0" stepSize="25"/>
  <ModelVariables>
"""


def _var(name: str, causality: str, variability: str, attrs: str = "") -> str:
    initial = ' initial="calculated"' if causality == "output" else ""
    real = f"<Real {attrs}/>" if attrs else "<Real/>"
    return (f'    <ScalarVariable name="{name}" valueReference="{{vr}}" causality="{causality}" '
            f'variability="{variability}"{initial}>{real}</ScalarVariable>\n')


def _variables(role: str) -> list[str]:
    fault = [_var("fault", "parameter", "tunable", 'start="0"'),
             _var("fault_time", "parameter", "tunable", 'start="1e300"')]
    if role == "controller":
        return [_var("h1", "input", "continuous", 'unit="m" start="0.65"'),
                _var("h2", "input", "continuous", 'unit="m" start="0.65"'),
                _var("ref.h1", "input", "continuous", 'unit="m" start="0.65"'),
                _var("ref.h2", "input", "continuous", 'unit="m" start="0.65"'),
                _var("qa", "output", "discrete", 'unit="m3/s" min="0" max="9.05e-4"'),
                _var("qb", "output", "discrete", 'unit="m3/s" min="0" max="11.1e-4"'),
                _var("status", "output", "discrete"), _var("fallback", "output", "discrete"),
                _var("iterations", "output", "discrete"), *fault]
    return [_var("h1", "output", "continuous", 'unit="m"'),
            _var("h2", "output", "continuous", 'unit="m"'),
            _var("qa", "input", "continuous", 'unit="m3/s" start="4.5e-4"'),
            _var("qb", "input", "continuous", 'unit="m3/s" start="5.5e-4"'), *fault]


def model_description(role: str) -> str:
    """The ``modelDescription.xml`` of ``role`` (value references from 1, ``model.h``)."""
    variables = _variables(role)
    body = "".join(v.replace("{vr}", str(i)) for i, v in enumerate(variables, start=1))
    outputs = [i for i, v in enumerate(variables, start=1) if 'causality="output"' in v]
    unknowns = "".join(f'      <Unknown index="{i}"/>\n' for i in outputs)
    return (_HEAD.format(ident=IDENTIFIERS[role]) + body + "  </ModelVariables>\n"
            "  <ModelStructure>\n    <Outputs>\n" + unknowns + "    </Outputs>\n"
            "    <InitialUnknowns>\n" + unknowns + "    </InitialUnknowns>\n"
            "  </ModelStructure>\n</fmiModelDescription>\n")


def build_spin(folder: Path) -> Path:
    """``folder/libspin.so``: ``hostile_spin()``, a C loop that never returns (``spin.c``)."""
    from cosim.core.build import compiler, run_compiler

    out = folder / "libspin.so"
    run_compiler([compiler(), "-shared", "-fPIC", "-O2", "-o", str(out), str(HERE / "spin.c")],
                 "libspin.so")
    return out


def build(role: str, folder: Path) -> Path:
    """Compile ``role`` (``"controller"`` or ``"plant"``) into ``folder/<Identifier>.fmu``."""
    from cosim.core.build import (
        CFLAGS,
        GLUE_DIR,
        LDFLAGS,
        add_member,
        compiler,
        fmi_headers_dir,
        run_compiler,
    )

    ident = IDENTIFIERS[role]
    binary = folder / f"{ident}.so"
    define = ["-DHOSTILE_CONTROLLER"] if role == "controller" else []
    flags = [f for f in CFLAGS if f != "-std=c99"]   # kill(), a POSIX function
    run_compiler([compiler(), *flags, "-std=gnu99", *define, f"-I{fmi_headers_dir()}",
                  f"-I{HERE}", f"-I{GLUE_DIR}", "-o", str(binary), str(HERE / "model.c"),
                  str(GLUE_DIR / "instance.c"), str(GLUE_DIR / "fmi2.c"), *LDFLAGS],
                 f"{ident}.fmu")
    out = folder / f"{ident}.fmu"
    with zipfile.ZipFile(out, "w") as zf:
        add_member(zf, "modelDescription.xml", model_description(role).encode())
        add_member(zf, f"binaries/linux64/{ident}.so", binary.read_bytes(), executable=True)
    binary.unlink()
    return out
