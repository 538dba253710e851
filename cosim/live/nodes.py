"""A live plant's nodes as the run finds them at connection, and what they must be to be used.

Each signal's tag (:mod:`cosim.live.tags`) is found on the server (a node id, or a browse
path walked from Objects or the root), then described (:class:`Node`): its data type, its
EngineeringUnits (the display name, else the UNECE code of the OPC UA "EUInformation"), its
EURange, and, for an input, whether this user may write it. Before anything is written to
the plant, :func:`check` refuses (one line naming the signal, the tag and both units, exit 2):

* a node whose data type is not a number;
* a unit that is not the tag's (the tags file's ``unit``), or, for a tag that declares none,
  not the problem's: a level published in % or in mm is never read as metres;
* an integer input node that cannot carry the input's box: fewer than :data:`MIN_STEPS`
  whole steps between its edges in the tag's units (5e-4 m³/s written into an Int16 is 0),
  or edges beyond the type's range;
* an input the user may not write.

The EURange is kept (in the tag's units): a measurement outside it is not used
(:mod:`cosim.live.session`).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from cosim.core.errors import CosimError
from cosim.live.tags import Tag

__all__ = ["INTEGER_RANGES", "MIN_STEPS", "UNECE", "Node", "check", "describe", "find",
           "same_unit", "server_unit", "type_of", "variant_type", "walk"]

#: The fewest whole steps an integer input node must resolve the input's box into.
MIN_STEPS = 100
#: The range of each integer data type an input may be written as.
INTEGER_RANGES = {"SByte": (-2 ** 7, 2 ** 7 - 1), "Byte": (0, 2 ** 8 - 1),
                  "Int16": (-2 ** 15, 2 ** 15 - 1), "UInt16": (0, 2 ** 16 - 1),
                  "Int32": (-2 ** 31, 2 ** 31 - 1), "UInt32": (0, 2 ** 32 - 1),
                  "Int64": (-2 ** 63, 2 ** 63 - 1), "UInt64": (0, 2 ** 64 - 1)}
#: Common UNECE Recommendation 20 codes (OPC UA Part 8, EUInformation.UnitId) as unit
#: strings, for a server that gives a code without a display name.
UNECE = {"MTR": "m", "MMT": "mm", "CMT": "cm", "KTM": "km", "P1": "%", "MQS": "m3/s",
         "MQH": "m3/h", "LTR": "L", "L2": "L/min", "G51": "L/s", "KEL": "K", "CEL": "degC",
         "BAR": "bar", "MBR": "mbar", "PAL": "Pa", "KPA": "kPa", "WTT": "W", "KWT": "kW",
         "SEC": "s", "MIN": "min", "HUR": "h", "KGM": "kg", "GRM": "g", "KGS": "kg/s",
         "KGH": "kg/h", "MTS": "m/s", "HTZ": "Hz", "C62": "1", "C34": "mol", "C38": "mol/L",
         "AMP": "A", "VLT": "V"}
#: Unicode spellings of units that servers display, as the ASCII the problem writes.
_ASCII = str.maketrans({"³": "3", "²": "2", "·": ".", "µ": "u", "°": "deg"})


@dataclass(frozen=True)
class Node:
    """A signal's node as the server describes it: the asyncua ``node``, the variant type it
    is written as (``vtype``), its data type's name, its unit (``None``: it declares none),
    its EURange in the tag's units (``None``: none) and whether this user may write it."""

    signal: str
    tag: Tag
    node: Any
    vtype: Any
    type_name: str
    unit: str | None
    eurange: tuple[float, float] | None
    writable: bool

    def summary(self) -> dict[str, Any]:
        """What the run's summary records of it."""
        return {"node": self.tag.describe() or str(self.node.nodeid.to_string()),
                "type": self.type_name, "unit": self.unit,
                "eurange": list(self.eurange) if self.eurange else None,
                "scale": self.tag.scale, "offset": self.tag.offset}


async def walk(start: Any, path: Sequence[tuple[int | None, str]], what: str) -> Any:
    """The node at browse ``path`` below ``start`` (a segment without a namespace index
    matches any)."""
    node = start
    for ns, name in path:
        for child in await node.get_children():
            q = await child.read_browse_name()
            if q.Name == name and (ns is None or q.NamespaceIndex == ns):
                node = child
                break
        else:
            raise CosimError(f"{what}: no node '{name}' below "
                             f"'{(await node.read_browse_name()).Name}'")
    return node


async def find(client: Any, base: Any, label: str, tag: Tag, endpoint: str) -> Any:
    """The node of ``tag`` (``label`` names it: ``signal 'h1'``): its node id, or its browse
    path from Objects or ``base`` (the root; ``None`` only when no tag needs it)."""
    from asyncua import ua

    what = f"{label} ({tag.describe()}{', ' + tag.where if tag.where else ''})"
    if tag.node_id is not None:
        node = client.get_node(tag.node_id)
        try:
            await node.read_browse_name()
        except ua.UaStatusCodeError:
            raise CosimError(f"--plant {endpoint}: {what}: no such node") from None
        return node
    return await walk(client.nodes.objects if tag.absolute else base, tag.path, what)


async def describe(node: Any, signal: str, tag: Tag, write: bool) -> Node:
    """``node``'s data type, unit, EURange and (``write``) access for this user."""
    from asyncua import ua

    dtype = await node.read_data_type()
    vtype = variant_type(dtype)
    type_name = vtype.name if vtype is not None else type_of(dtype)
    unit, eurange = None, None
    with contextlib.suppress(ua.UaError, ValueError, AttributeError, TypeError):
        eu = await (await node.get_child(["0:EngineeringUnits"])).read_value()
        unit = server_unit(eu)
    with contextlib.suppress(ua.UaError, ValueError, AttributeError, TypeError):
        rng = await (await node.get_child(["0:EURange"])).read_value()
        lo, hi = float(rng.Low), float(rng.High)
        if math.isfinite(lo) and math.isfinite(hi) and lo < hi:
            eurange = (lo, hi)
    writable = False
    if write:
        level = await node.read_attribute(ua.AttributeIds.UserAccessLevel)
        writable = bool(int(level.Value.Value) & ua.AccessLevel.CurrentWrite.mask)
    return Node(signal, tag, node, vtype, type_name, unit, eurange, writable)


def check(node: Node, problem_unit: str, box: tuple[float, float] | None,
          endpoint: str) -> None:
    """Refuse a node the run cannot use as it is (module docstring); ``box`` is an input's
    (``None`` for a measurement).

    Raises
    ------
    CosimError
        One line naming the signal, its tag and what is wrong.
    """
    tag, signal = node.tag, node.signal
    what = f"--plant {endpoint}: signal '{signal}' ({tag.describe()})"
    if node.vtype is None:
        raise CosimError(f"{what}: its data type {node.type_name} is not a number")
    want = tag.unit or problem_unit
    if node.unit is not None and not same_unit(node.unit, want):
        declared = (f"the tags file's '{tag.unit}' (the problem's: '{problem_unit}')"
                    if tag.unit else f"the problem's '{problem_unit}'")
        raise CosimError(f"{what}: the server's unit is '{node.unit}' (its "
                         f"EngineeringUnits), not {declared}: give the tag its unit, scale "
                         f"and offset in the tags file ([tags.{signal}] unit = "
                         f"\"{node.unit}\", scale, offset)")
    if box is None:
        return
    if not node.writable:
        raise CosimError(f"{what}: input '{signal}' is not writable by this user")
    limits = INTEGER_RANGES.get(node.type_name)
    if limits is None:
        return
    lo, hi = sorted((tag.to_plant(box[0]), tag.to_plant(box[1])))
    if hi - lo < MIN_STEPS:
        why = f"fewer than {MIN_STEPS} whole steps"
    elif lo < limits[0] or hi > limits[1]:
        why = f"beyond the type's range [{limits[0]}, {limits[1]}]"
    else:
        return
    raise CosimError(f"{what}: an {node.type_name} node cannot carry the input's box "
                     f"[{box[0]:g}, {box[1]:g}] {problem_unit} ({lo:g} to {hi:g} in the "
                     f"tag's units: {why}); give the tag a unit and scale in the tags file "
                     f"([tags.{signal}] unit, scale, offset)")


def server_unit(eu: Any) -> str | None:
    """The unit an OPC UA ``EUInformation`` says: its display name, else its UNECE code
    (:data:`UNECE`, else ``"UNECE <code>"``); ``None`` when it says none."""
    text = getattr(getattr(eu, "DisplayName", None), "Text", None)
    if isinstance(text, str) and text.strip():
        return text.strip()
    unit_id = getattr(eu, "UnitId", None)
    if not isinstance(unit_id, int) or unit_id <= 0:
        return None
    code = unit_id.to_bytes(4, "big").lstrip(b"\0").decode("ascii", "replace")
    return UNECE.get(code, f"UNECE {code}")


def same_unit(a: str, b: str) -> bool:
    """Whether two unit strings name the same unit (``m³/s`` and ``m3/s``; ``mm`` and ``m``
    do not)."""
    a2, b2 = (u.strip().translate(_ASCII) for u in (a, b))
    if a2 == b2:
        return True
    from cosim.core.binding import unit_conversion

    try:
        conv = unit_conversion(a2, b2)
    except CosimError:
        return False
    return math.isclose(conv.scale, 1.0, rel_tol=1e-9) and abs(conv.offset) < 1e-12


def type_of(dtype: Any) -> str:
    """A DataType node id's name (``Boolean``, ``String``), else the node id."""
    from asyncua import ua

    if dtype.NamespaceIndex == 0:
        with contextlib.suppress(ValueError):
            return ua.VariantType(dtype.Identifier).name
    return str(dtype.to_string())


def variant_type(dtype: Any) -> Any:
    """The variant type to read and write a node whose DataType is ``dtype``; ``None`` when
    it is not a number (a Boolean, a String, a structure)."""
    from asyncua import ua

    V = ua.VariantType
    numeric = (V.Double, V.Float, V.SByte, V.Byte, V.Int16, V.UInt16, V.Int32, V.UInt32,
               V.Int64, V.UInt64)
    if dtype.NamespaceIndex == 0:
        with contextlib.suppress(ValueError):
            vt = V(dtype.Identifier)
            if vt in numeric:
                return vt
        if dtype.Identifier in (ua.ObjectIds.Number, ua.ObjectIds.BaseDataType):
            return V.Double
    return None
