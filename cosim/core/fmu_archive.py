"""An FMU file before it runs: its archive, its modelDescription, its native binary.

An ``.fmu`` is a zip archive; :func:`safe_extract` unpacks it after checking every member
name and the unpacked size, :func:`read_model_description` reads its ``modelDescription.xml``
(through fmpy), :func:`plant_variables` the plant variables a controller FMU records, and
:func:`check_binary` checks that it has a binary for this platform. Each fault is a one-line
:class:`~cosim.core.errors.CosimError` naming the FMU.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path, PurePosixPath
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["MAX_UNPACKED_BYTES", "PLANT_ANNOTATION", "check_binary", "plant_variables",
           "read_model_description", "safe_extract", "why_not_valid"]

#: Refuse archives that would unpack to more than this many bytes (zip bombs).
MAX_UNPACKED_BYTES = 2 * 1024**3


def safe_extract(path: Path, into: Path) -> Path:
    """Extract an FMU archive after checking every member name.

    Rejects absolute paths, drive letters, backslashes, ``..`` components and archives that
    would unpack to more than :data:`MAX_UNPACKED_BYTES`.

    Raises
    ------
    CosimError
        Naming the FMU and the offending member.
    """
    try:
        with zipfile.ZipFile(path) as zf:
            total = 0
            for info in zf.infolist():
                name = info.filename
                parts = PurePosixPath(name).parts
                if (name.startswith("/") or "\\" in name or ":" in name or ".." in parts):
                    raise CosimError(f"{path}: unsafe path '{name}' in the FMU archive")
                total += info.file_size
            if total > MAX_UNPACKED_BYTES:
                raise CosimError(f"{path}: archive unpacks to {total} bytes, more than allowed")
            zf.extractall(into)
    except zipfile.BadZipFile as exc:
        raise CosimError(f"{path}: not an FMU (not a zip archive: {exc})") from None
    return into


def read_model_description(path: str | Path) -> Any:
    """``fmpy.read_model_description`` with errors as one-line :class:`CosimError`."""
    import fmpy

    path = Path(path)
    if path.is_dir():
        raise CosimError(f"{path}: is a folder, not an FMU file (.fmu zip archive)")
    if not path.is_file():
        raise CosimError(f"{path}: FMU not found")
    try:
        return fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:
        msg = " ".join(str(exc).split())
        raise CosimError(f"{path}: cannot read modelDescription.xml: {msg}") from None


def check_binary(path: Path, unzipped: Path, model_identifier: str, fmi3: bool) -> None:
    """Raise :class:`CosimError` if the FMU unpacked in ``unzipped`` has no binary for this
    platform (``path`` is the ``.fmu`` file, for the message)."""
    import fmpy

    platform = fmpy.platform_tuple if fmi3 else fmpy.platform
    rel = f"binaries/{platform}/{model_identifier}{fmpy.sharedLibraryExtension}"
    if (unzipped / rel).is_file():
        return
    bins = unzipped / "binaries"
    have = sorted(p.name for p in bins.iterdir() if p.is_dir()) if bins.is_dir() else []
    also = f" (it has binaries for: {', '.join(have)})" if have else " (it has no binaries)"
    raise CosimError(f"{path}: no binary for this platform: '{rel}' is missing{also}")


def why_not_valid(var: Any, value: float) -> str:
    """Why ``value`` cannot be given to the modelDescription's variable ``var`` (``""`` when it
    can): not finite, or outside the box its ``min`` and ``max`` declare."""
    if not math.isfinite(value):
        return "expected a finite number"
    low = float(var.min) if var.min is not None else -math.inf
    high = float(var.max) if var.max is not None else math.inf
    return "" if low <= value <= high else f"outside its range [{low:g}, {high:g}]"


#: The tool of the FMI 2 vendor annotation, the type of the FMI 3 annotation, in which a
#: controller FMU of ``cosim export-fmu`` records the plant variable of each signal.
PLANT_ANNOTATION = "org.gru-mpc-cosim.plant-variables"


def plant_variables(path: str | Path) -> dict[str, str]:
    """The plant variable of each signal of the controller FMU ``path``, as its
    modelDescription records it (:data:`PLANT_ANNOTATION`), by the controller's variable name;
    empty for an FMU without the record (an export older than it, another tool's): its
    signals are the plant's variables of their own names.

    Raises
    ------
    CosimError
        ``path`` is no FMU or its modelDescription.xml is no XML.
    """
    import xml.etree.ElementTree as ET

    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError) as exc:
        raise CosimError(f"{path}: cannot read modelDescription.xml: "
                         f"{' '.join(str(exc).split())}") from None
    holders = [*root.iterfind("VendorAnnotations/Tool"),
               *root.iterfind("Annotations/Annotation")]
    out = {}
    for holder in holders:
        if PLANT_ANNOTATION in (holder.get("name"), holder.get("type")):
            for var in holder.iter("Variable"):
                name, plant = var.get("name"), var.get("plant")
                if name and plant:
                    out[name] = plant
    return out
