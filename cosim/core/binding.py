"""Binding a control problem to a plant FMU: which variable each signal is, and in what unit.

A control problem names its signals in its own units (a problem file: ``[inputs.F]``,
``unit = "L/min"``); a plant FMU has variables with their own names and units. :func:`bind`
matches the two before anything runs and returns the :class:`~cosim.core.varmap.VarMap` through
which :class:`~cosim.core.fmu.FmuComponent` renames and converts (``value_fmu = scale *
value_problem + offset`` on the way in, the inverse on the way out):

- **Names.** A signal is the FMU variable of its own name, or the one its problem entry names
  (``variable = "F_in"``). A variable map (``--map``, :mod:`cosim.core.varmap`) takes precedence:
  an entry with a ``scale`` or an ``offset`` is taken as it is; an entry without either only
  renames, and the units decide the conversion as for any other signal.
- **Units.** The problem's unit is related to the unit the FMU declares for the variable (its
  ``unit`` attribute, or its declared type's; FMI 2.0 and 3.0 alike), by
  :func:`unit_conversion`: the FMU's own ``<UnitDefinitions>`` when both units are defined
  there with the same base-unit exponents (the FMI 2.0 and 3.0 standards, "Definition of
  Units", ``<BaseUnit>``: ``BaseUnit_value = factor * Unit_value + offset``), else pint
  (offset units such as ``degC`` included), with the Modelica unit syntax FMUs write
  (``m3/s``, ``kg.m2``, ``s-1``; the Modelica Language Specification, "Unit Expressions")
  read as pint's. An FMU variable without a unit is taken in the problem's unit.
- **Checks**, each one line naming where the signal is declared (``problem.toml:12``, or the
  map file), the signal and the FMU variable: a variable the FMU lacks; the wrong causality
  (a problem input must be an FMU input or a tunable parameter, an output an FMU output); a
  variable that is not a real scalar; a unit the FMU contradicts (other dimensions); a unit
  string that neither the FMU nor pint understands (with a suggested spelling).

The binding takes plain data (:class:`Wanted`: signal name, variable, unit, role) and the
FMU's model description as fmpy reads it; it imports nothing of the numerical core.
"""

from __future__ import annotations

import difflib
import math
import re
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError
from cosim.core.varmap import MappedSignal, VarMap, variable_unit

__all__ = ["Conversion", "UnitError", "Wanted", "bind", "pint_units", "unit_conversion",
           "unit_definitions"]

#: fmpy's type names of real-valued variables (FMI 2.0, FMI 3.0).
_REAL_TYPES = ("Real", "Float64")
#: The SI base units of an FMI ``<BaseUnit>`` (``rad`` is FMI's eighth, dimensionless in pint).
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd")
#: pint's dimension of each base unit.
_PINT_DIMENSIONS = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[current]": "A",
                    "[temperature]": "K", "[substance]": "mol", "[luminosity]": "cd"}
#: Modelica unit syntax → pint: an exponent written after its symbol (``m3``, ``s-1``) ...
_EXPONENT = re.compile(r"(?<=[A-Za-z_\u00b0\u00b5\u03a9])([+-]?\d+)")
#: ... and ``.`` as the product (``N.m``).
_PRODUCT = re.compile(r"(?<=[A-Za-z0-9_])\.(?=[A-Za-z_])")
#: Spellings shown when a unit is not understood and nothing close is found.
_EXAMPLES = '"m3/s", "L/min", "degC", "K", "mol/L", "1"'


@dataclass(frozen=True)
class Wanted:
    """One signal of a control problem as the binding needs it (plain data).

    Attributes
    ----------
    name : str
        The problem's name of the signal.
    variable : str
        The FMU variable the problem names for it (its own name unless ``variable`` says).
    unit : str
        The problem's unit.
    role : {"input", "output", "disturbance"}
        A manipulated input or a measured disturbance (written into the FMU), or a measured
        output (read from it).
    where : str
        Where the signal is declared (``problem.toml:12``), for messages.
    unit_where : str
        Where its unit is declared (default: :attr:`where`).
    """

    name: str
    variable: str
    unit: str
    role: str
    where: str = "<problem>"
    unit_where: str = ""


@dataclass(frozen=True)
class Conversion:
    """``value_fmu = scale * value_problem + offset`` and how it was found (``via``: ``"same"``
    for equal strings, ``"fmu"`` the FMU's UnitDefinitions, ``"pint"``, or ``"fmu+pint"``
    one unit from each)."""

    scale: float = 1.0
    offset: float = 0.0
    via: str = "same"

    @property
    def identity(self) -> bool:
        return self.scale == 1.0 and self.offset == 0.0


class UnitError(CosimError):
    """Two units that cannot be related: ``kind`` is ``"contradiction"`` (other dimensions) or
    ``"unknown"`` (a unit string nobody understands); the message is a phrase without a
    location (:func:`bind` adds it)."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


# ---------------------------------------------------------------------------------------------
# Units
# ---------------------------------------------------------------------------------------------

def unit_definitions(md: Any) -> dict[str, Any]:
    """The FMU's ``<UnitDefinitions>``: unit name → its fmpy ``BaseUnit`` (``kg``, ``m``,
    ``s``, ``A``, ``K``, ``mol``, ``cd``, ``rad``, ``factor``, ``offset``); units declared
    without a ``<BaseUnit>`` are left out (they say nothing about dimensions)."""
    out = {}
    for unit in getattr(md, "unitDefinitions", None) or ():
        base = getattr(unit, "baseUnit", None)
        if unit.name and base is not None:
            out[unit.name] = base
    return out


_PINT: list[Any] = []
_PINT_LOCK = threading.Lock()


def pint_units() -> Any:
    """The pint ``UnitRegistry`` (built once per process, on first use: ~0.3 s)."""
    with _PINT_LOCK:
        if not _PINT:
            import pint

            _PINT.append(pint.UnitRegistry())
        return _PINT[0]


def _pint_text(unit: str) -> str:
    """A unit string in Modelica syntax (``m3/s``, ``N.m``, ``s-1``) as pint reads it."""
    return _EXPONENT.sub(r"**\1", _PRODUCT.sub("*", unit.strip()))


def _pint_parse(unit: str) -> tuple[Any, str | None]:
    """``(quantity of 1 unit, None)``, or ``(None, the token pint does not know)``."""
    ureg = pint_units()
    try:
        return ureg.Quantity(1.0, _pint_text(unit)), None
    except Exception as exc:  # UndefinedUnitError, and pint's parser on garbage
        names = getattr(exc, "unit_names", None)
        token = names[0] if isinstance(names, tuple) and names else names
        return None, token if isinstance(token, str) and token else unit


def si_base_unit(unit: str) -> dict[str, float] | None:
    """The FMI ``<BaseUnit>`` of a unit string (Modelica syntax): SI exponents (``kg``, ``m``,
    ``s``, ``A``, ``K``, ``mol``, ``cd``; zeros left out) and ``factor``, ``offset`` when not
    1 and 0 (``value_SI = factor · value + offset``, 15 significant digits); ``None`` when
    pint does not know the unit."""
    q1, _ = _pint_parse(unit)
    if q1 is None:
        return None
    ureg = pint_units()
    zero = ureg.Quantity(0.0, q1.units).to_base_units().magnitude
    one = q1.to_base_units().magnitude
    dims = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[current]": "A",
            "[temperature]": "K", "[substance]": "mol", "[luminosity]": "cd"}
    out: dict[str, float] = {dims[d]: int(e) for d, e in q1.dimensionality.items()
                             if d in dims and e}
    factor, offset = float(f"{one - zero:.15g}"), float(f"{zero:.15g}")
    if factor != 1.0:
        out["factor"] = factor
    if offset != 0.0:
        out["offset"] = offset
    return out


def _suggest(token: str, extra: Iterable[str]) -> str:
    """``; did you mean 'x'?`` for a unit token, or a few spellings that work."""
    names = [*extra, *pint_units()._units]
    lower = {n.lower(): n for n in names}
    close = [lower[token.lower()]] if token.lower() in lower else [
        lower[m] for m in difflib.get_close_matches(token.lower(), list(lower), n=3,
                                                    cutoff=0.75)]
    if close:
        return f"; did you mean {' or '.join(repr(c) for c in close)}?"
    return f"; write it like {_EXAMPLES}"


def _fmi_exponents(base: Any) -> tuple[int, ...]:
    return tuple(int(getattr(base, k, 0) or 0) for k in _BASE)


def _pint_si(q: Any) -> tuple[tuple[int, ...], float, float] | None:
    """Base-unit exponents, factor and offset (``SI = factor * value + offset``) of a pint
    unit, or ``None`` when it has a dimension FMI has no base unit for."""
    dims = dict(q.dimensionality)
    if any(d not in _PINT_DIMENSIONS for d in dims):
        return None
    exps = tuple(int(dims.get(d, 0)) for d in _PINT_DIMENSIONS)
    zero = float(q.__class__(0.0, q.units).to_base_units().magnitude)
    one = float(q.__class__(1.0, q.units).to_base_units().magnitude)
    return exps, one - zero, zero


def _dimension_text(exps: tuple[int, ...]) -> str:
    parts = [f"{b}{'' if e == 1 else e}" for b, e in zip(_BASE, exps, strict=True) if e]
    return ".".join(parts) or "1"


def unit_conversion(problem_unit: str, fmu_unit: str,
                    definitions: Mapping[str, Any] | None = None) -> Conversion:
    """The affine map from ``problem_unit`` to ``fmu_unit``: ``value_fmu = scale *
    value_problem + offset``.

    Parameters
    ----------
    problem_unit, fmu_unit : str
        Unit strings (Modelica syntax as FMUs write them, or pint's).
    definitions : mapping, optional
        The FMU's unit definitions (:func:`unit_definitions`).

    Returns
    -------
    Conversion
        Equal strings: the identity. Both defined by the FMU with the same base-unit
        exponents: from their ``BaseUnit`` factors and offsets (``SI = factor * value +
        offset``, FMI 2.0 and 3.0, "Definition of Units"), so ``scale = f_p / f_f`` and
        ``offset = (o_p − o_f) / f_f``. Else pint's offset-aware conversion of the two
        strings; else, one unit defined by the FMU and the other known to pint, both through
        SI.

    Raises
    ------
    UnitError
        ``kind="contradiction"``: the units have other dimensions; ``kind="unknown"``: a
        string neither the FMU defines nor pint knows (the message suggests a spelling).
    """
    if problem_unit == fmu_unit:
        return Conversion()
    defs = definitions or {}
    dp, df = defs.get(problem_unit), defs.get(fmu_unit)
    if dp is not None and df is not None and _fmi_exponents(dp) == _fmi_exponents(df):
        fp, ff = float(dp.factor), float(df.factor)
        return Conversion(fp / ff, (float(dp.offset) - float(df.offset)) / ff, "fmu")
    qp, bad_p = _pint_parse(problem_unit)
    qf, bad_f = _pint_parse(fmu_unit)
    if qp is not None and qf is not None:
        if qp.dimensionality != qf.dimensionality:
            raise UnitError(f"'{problem_unit}' is {qp.dimensionality} but '{fmu_unit}' is "
                            f"{qf.dimensionality}", "contradiction")
        try:
            zero = float(qp.__class__(0.0, qp.units).to(qf.units).magnitude)
            one = float(qp.__class__(1.0, qp.units).to(qf.units).magnitude)
        except Exception as exc:  # an offset unit inside a product (pint refuses those)
            raise UnitError(f"pint cannot convert '{problem_unit}' to '{fmu_unit}' "
                            f"({' '.join(str(exc).split())})", "unknown") from None
        return Conversion(one - zero, zero, "pint")
    # one side only the FMU defines, the other only pint knows: compare them in SI
    sides = []
    for unit, base, q, bad in ((problem_unit, dp, qp, bad_p), (fmu_unit, df, qf, bad_f)):
        if base is not None:
            sides.append((_fmi_exponents(base), float(base.factor), float(base.offset)))
        elif q is not None and _pint_si(q) is not None:
            sides.append(_pint_si(q))
        else:
            who = "the problem's" if unit == problem_unit else "the FMU's"
            raise UnitError(f"{who} unit '{unit}' is not understood (not in the FMU's "
                            f"UnitDefinitions, and pint does not know '{bad}'"
                            f"{_suggest(bad or unit, defs)})", "unknown")
    (ep, fp, op), (ef, ff, of) = sides
    if ep != ef:
        raise UnitError(f"'{problem_unit}' is {_dimension_text(ep)} but '{fmu_unit}' is "
                        f"{_dimension_text(ef)}", "contradiction")
    return Conversion(fp / ff, (op - of) / ff, "fmu+pint")


# ---------------------------------------------------------------------------------------------
# Binding
# ---------------------------------------------------------------------------------------------

def _check_role(where: str, w: Wanted, var: Any) -> None:
    """Causality, type and shape of the variable ``w`` is bound to."""
    causality, variability = getattr(var, "causality", None), getattr(var, "variability", None)
    if w.role in ("input", "disturbance"):
        if not (causality == "input" or (causality == "parameter" and variability == "tunable")):
            what = f"a {variability} parameter" if causality == "parameter" else \
                f"of causality '{causality}'"
            raise CosimError(f"{where}: the variable is {what}; a problem {w.role} must be an "
                             "FMU input or a tunable parameter")
    elif causality != "output":
        raise CosimError(f"{where}: the variable is of causality '{causality}'; a problem "
                         "output must be an FMU output")
    kind = getattr(var, "type", None)
    if kind not in _REAL_TYPES:
        raise CosimError(f"{where}: the variable is of type '{kind}'; a problem signal must be "
                         "a real (Real, Float64) variable")
    if getattr(var, "dimensions", None):
        raise CosimError(f"{where}: the variable is an array; a problem signal must be a "
                         "scalar")


def _conversion(w: Wanted, where: str, fmu_unit: str | None, defs: Mapping[str, Any],
                fmu: str) -> Conversion:
    if not fmu_unit:
        return Conversion()
    try:
        return unit_conversion(w.unit, fmu_unit, defs)
    except UnitError as exc:
        if exc.kind == "contradiction":
            raise CosimError(f"{where}: a unit the FMU contradicts: the problem says "
                             f"'{w.unit}', {fmu} declares '{fmu_unit}' ({exc})") from None
        raise CosimError(f"{where}: {exc}") from None


def bind(wanted: Iterable[Wanted], md: Any, fmu: str | Path,
         user_map: VarMap | None = None, source: str = "<problem>") -> VarMap:
    """Bind the problem's signals to the FMU's variables (see the module docstring).

    Parameters
    ----------
    wanted : iterable of Wanted
        The problem's inputs and outputs.
    md : fmpy ModelDescription
        The plant FMU's (``modelVariables``, ``unitDefinitions``).
    fmu : str or Path
        The FMU file, named in messages.
    user_map : VarMap, optional
        A variable map (``--map``): its entries take precedence.
    source : str
        The problem's file (the path of the returned map when no ``user_map`` is given).

    Returns
    -------
    VarMap
        ``user_map`` (or the identity) when nothing needs renaming or converting; else a map
        with an entry per renamed or converted signal (``unit`` the FMU's) besides the
        ``user_map``'s own.

    Raises
    ------
    CosimError
        One line: the map's or the problem file's location, the signal, the variable and
        what is wrong (module docstring, "Checks").
    """
    fmu_name = Path(fmu).name
    variables = {v.name: v for v in md.modelVariables}
    defs = unit_definitions(md)
    user = user_map or VarMap.identity()
    user.check_entries(variables)
    entries = dict(user.signals)
    taken = {m.variable: m.signal for m in user.signals.values()}
    for w in wanted:
        mapped = user.signals.get(w.name)
        if mapped is not None:
            where = f"{user.path}: signal '{w.name}' -> variable '{mapped.variable}'"
            var = variables[mapped.variable]
            _check_role(where, w, var)
            if mapped.scale == 1.0 and mapped.offset == 0.0:  # a rename: the units decide
                fmu_unit = variable_unit(var) or mapped.unit
                conv = _conversion(w, where, fmu_unit, defs, fmu_name)
                entries[w.name] = MappedSignal(w.name, mapped.variable, fmu_unit or None,
                                               conv.scale, conv.offset)
            continue
        where = f"{w.where}: {w.role} '{w.name}' -> FMU variable '{w.variable}'"
        var = variables.get(w.variable)
        if var is None:
            hint = (" (name the FMU's variable with variable = \"...\" in the problem, or map "
                    "it with --map)")
            raise CosimError(f"{where}: {fmu_name} has no such variable{hint}")
        other = taken.get(w.variable)
        if other is not None:
            raise CosimError(f"{where}: the variable map {user.path} binds that variable to "
                             f"signal '{other}' already")
        taken[w.variable] = w.name
        _check_role(where, w, var)
        fmu_unit = variable_unit(var)
        uwhere = f"{w.unit_where or w.where}: {w.role} '{w.name}' -> FMU variable '{w.variable}'"
        conv = _conversion(w, uwhere, fmu_unit, defs, fmu_name)
        if w.variable != w.name or not conv.identity or (fmu_unit and fmu_unit != w.unit):
            entries[w.name] = MappedSignal(w.name, w.variable, fmu_unit or None, conv.scale,
                                           conv.offset)
    if entries == dict(user.signals):
        return user
    for m in entries.values():
        if not (math.isfinite(m.scale) and m.scale != 0.0 and math.isfinite(m.offset)):
            raise CosimError(f"{fmu_name}: signal '{m.signal}' -> variable '{m.variable}': "
                             f"the unit conversion is degenerate (scale {m.scale!r})")
    path = user.path if user_map is not None else Path(source)
    return VarMap(path=path, signals=entries)
