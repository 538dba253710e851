"""The robust MPC exported as a controller FMU: from a :class:`~cosim.adapters.robust_mpc.
RobustMPCController` to :func:`cosim.core.controller_fmu.build_controller_fmu`.

The FMU runs the same step as the Python component, in C: the component's own observer,
FHOCP (set up on its compiled kernel), law, scalings and input box become the numbers of
:mod:`controllers.kernel.controller_source` (data in the FMU's resources: one binary for
every design of the same dimensions, signals and law), and the problem's signals the FMU's
variables (measured outputs and set-points ``ref.<output>`` in, the inputs to apply out,
named and in the units of the problem; docs: guide/controller-fmu.md). Both laws are
exported, for any numbers of inputs and outputs: the tracking law (the default) and the
paper's, with ``offset_free`` and ``setpoint_rate`` as in Python, with its reference governor
(its default) or without it (``governor=false``: the paper's controller).
"""

from __future__ import annotations

import hashlib
import re
import uuid
from pathlib import Path
from typing import Any

from cosim.core.controller_fmu import ControllerInterface, Parameter, Port, build_controller_fmu
from cosim.core.errors import CosimError

__all__ = ["export_fmu", "fmu_identifier"]


def fmu_identifier(out: str | Path) -> str:
    """The FMU's model identifier from its file name: ``Controller.fmu`` → ``Controller``
    (other characters than letters, digits and ``_`` become ``_``)."""
    stem = re.sub(r"\W", "_", Path(out).name.removesuffix(".fmu"), flags=re.ASCII)
    return stem if stem and not stem[0].isdigit() else f"C{stem}"


def _why_not(ctrl: Any) -> str:
    """Why ``ctrl`` cannot be exported (empty: it can)."""
    fhocp = ctrl.mpc.fhocp
    if fhocp.kernel is None or not fhocp._compiled_loop:
        reason = fhocp.kernel_error or "the options select another solver"
        return f"the controller FMU runs the compiled kernel's SQP, unavailable here ({reason})"
    if ctrl.previewed:
        return (f"preview = true on {', '.join(ctrl.previewed)}: the controller FMU measures "
                "its disturbances and is told nothing ahead (declare them without preview to "
                "export)")
    return ""


def _operator_ports(ctrl: Any, design: Any) -> tuple[Parameter, ...]:
    """The FMU's operator inputs (:func:`controllers.kernel.controller_source.
    operator_names`, ``operator.c``'s order) with their ranges, units and defaults (the
    Python controller's :meth:`~cosim.adapters.robust_mpc.RobustMPCController.settings`)."""
    from controllers.kernel.controller_source import operator_names

    pr = ctrl.problem
    settings = ctrl.settings()
    return tuple(Parameter(name, settings[name].unit or "1", settings[name].low,
                           settings[name].high, settings[name].description,
                           start=settings[name].start)
                 for name in operator_names(design, pr.input_names, pr.output_names))


def export_fmu(ctrl: Any, out: str | Path, fmi_version: int = 3) -> Path:
    """Build the controller FMU of ``ctrl`` (a robust MPC) at ``out`` (FMI 2 or 3); returns
    ``out``. Raises :class:`CosimError` (one line) when it cannot be exported or built."""
    from controllers.kernel.compiled_kernel import PREFIX_PLACEHOLDER, variant_flags
    from controllers.kernel.controller_source import (
        design_data,
        generate_source,
        parameters,
    )

    if not str(out).endswith(".fmu"):
        raise CosimError(f"--out {out}: an FMU's file name ends with .fmu")
    ctrl.setup(0.0)   # its solver built (again after a switch to the uncertified mode)
    why = _why_not(ctrl)
    if why:
        raise CosimError(f"cannot export {ctrl.model_path}: {why}")
    mpc = ctrl.mpc
    spec = mpc.options.spec
    design = mpc.export_design()
    title = spec.hook("export", "title")(mpc.law)
    source = generate_source(design).replace(PREFIX_PLACEHOLDER, "mpc_")
    flags, _ = variant_flags(design.kernel, (), blas=False)
    pr = ctrl.problem
    digest = hashlib.sha256(source.encode()).hexdigest()
    certified = "certified" if mpc.certification.certified else "uncertified"
    iface = ControllerInterface(
        identifier=fmu_identifier(out), token="{" + str(uuid.UUID(hex=digest[:32])) + "}",
        description=(f"Robust GRU MPC (Schimperna & Magni), {title}, {certified}: model "
                     f"{Path(ctrl.model_path).name}, problem {pr.name}, N={mpc.fhocp.N}"),
        sample_time=float(ctrl.sample_time),
        measured=tuple(Port(c.name, c.unit, c.min, c.max, c.description or "",
                            c.variable) for c in pr.outputs),
        applied=tuple(Port(c.name, c.unit, c.min, c.max, c.description or "",
                           c.variable) for c in pr.inputs),
        disturbances=tuple(Port(c.name, c.unit, c.min, c.max, c.description or "",
                                c.variable) for c in pr.disturbances),
        parameters=tuple(Parameter(name, "1", low, high, text, start=start)
                         for name, low, high, text, start in parameters(
                             design, pr.input_names, pr.output_names)),
        operator=_operator_ports(ctrl, design))
    return build_controller_fmu(iface, source, design_data(design), out,
                                fmi_version=fmi_version, flags=flags)
