"""The signal tables of a control-problem file, and the checks of single values.

A signal table (``[inputs.NAME]``, ``[outputs.NAME]``, ``[disturbances.NAME]`` in TOML, the
channel lists of the JSON form) becomes a :class:`~controllers.problem.Channel`: its name, unit
and box, the FMU variable it is, its normalisation, its excitation in ``cosim generate-data``
(``hold``, ``levels``), its dead time (``delay``, at most :data:`MAX_DELAY` samples), a
disturbance's ``rate`` and ``preview``, an input's ``safe`` value, and what a live run takes
for a plausible measurement (``valid``, an output's ``rate``, ``frozen``: at most
:data:`MAX_FROZEN` samples). Every fault is one
:class:`~controllers.errors.ProblemFileError` (exit 2) located by ``where(table, key)``: a
file's line, or the key's path in the JSON form. The checks of single values (a finite
number, a pair, a required key, a non-empty string) serve the file's other tables too
(:mod:`controllers.problem_file`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any

from controllers.errors import ProblemFileError
from controllers.problem import Channel

__all__ = ["MAX_DELAY", "MAX_FROZEN", "NAME", "Where", "channel", "number", "pair", "require",
           "table_name", "text"]

#: The keys of every signal's table; each kind adds its own.
_CHANNEL = {"unit", "min", "max", "variable", "description", "normalization"}
#: What a live run takes for a plausible measurement (outputs, disturbances).
_PLAUSIBLE = {"valid", "frozen"}
_OUTPUT = _CHANNEL | _PLAUSIBLE | {"rate", "limit_rate"}
_INPUT = _CHANNEL | {"hold", "levels", "delay", "safe", "max_move"}
_DISTURBANCE = (_INPUT - {"safe", "max_move"}) | _PLAUSIBLE | {"rate", "preview"}
#: The longest dead time a signal may declare [samples].
MAX_DELAY = 50
#: The most samples ``frozen`` may count.
MAX_FROZEN = 10_000
#: The keys of ``normalization = { offset, scale }``.
_NORM = {"offset", "scale"}
#: Names a signal may have (they become column names: ``ref.<name>``, ``iae.<name>``).
NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

#: ``where(table, key)`` → the message prefix locating ``key`` of ``table``.
Where = Callable[[str, "str | None"], str]


def number(value: Any, at: str, key: str) -> float:
    """``value`` of ``key`` as a finite float (not a boolean)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProblemFileError(f"{at}: '{key}' must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ProblemFileError(f"{at}: '{key}' must be finite, got {value!r}")
    return float(value)


def require(table: dict[str, Any], keys: tuple[str, ...], at: str, label: str) -> None:
    """Fail on the first of ``keys`` that ``table`` (named ``label``, at ``at``) lacks."""
    for key in keys:
        if key not in table:
            raise ProblemFileError(f"{at}: {label} has no '{key}'")


def text(value: Any, at: str, key: str, *, empty: bool = False, hint: str = "") -> str:
    """``value`` of ``key``: a string (``empty``: any, as it is), else a non-empty one,
    stripped (its message ends with ``hint``)."""
    if empty:
        if not isinstance(value, str):
            raise ProblemFileError(f"{at}: '{key}' must be a string")
        return value
    if not isinstance(value, str) or not value.strip():
        raise ProblemFileError(f"{at}: '{key}' must be a non-empty string{hint}")
    return value.strip()


def pair(value: Any, at: str, key: str, integer: bool = False) -> tuple[float, float]:
    """``value`` of ``key`` as ``[low, high]``: two numbers (whole ones when ``integer``)."""
    if not isinstance(value, list) or len(value) != 2:
        raise ProblemFileError(f"{at}: '{key}' must be a list of two numbers [low, high]")
    if integer and not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ProblemFileError(f"{at}: '{key}' must be two whole numbers of samples")
    lo, hi = (number(v, at, key) for v in value)
    return lo, hi


def table_name(kind: str, name: Any, index: int, toml: bool) -> str:
    """How messages name signal ``index`` of ``kind``: ``inputs.F`` in TOML, ``inputs[0]``
    in the JSON form."""
    return f"{kind}.{name}" if toml else f"{kind}[{index}]"


def channel(entry: Any, kind: str, index: int, where: Where, toml: bool) -> Channel:
    """Signal ``index`` of ``kind`` (``"inputs"``, ``"outputs"``, ``"disturbances"``),
    checked: its table ``entry`` (with its ``name``) as a :class:`Channel`."""
    if not isinstance(entry, dict):
        raise ProblemFileError(f"{where(kind)}: {kind} entry {index} must be a table")
    name = entry.get("name")
    table = table_name(kind, name, index, toml)
    if not isinstance(name, str) or not NAME.match(name):
        raise ProblemFileError(f"{where(table)}: signal name {name!r} must start with a "
                               "letter and hold only letters, digits and '_' (it names "
                               "columns such as ref.<name>)")
    allowed = ({"inputs": _INPUT, "outputs": _OUTPUT, "disturbances": _DISTURBANCE}[kind]
               | ({"name"} if not toml else set()))
    unknown = [k for k in entry if k not in allowed and k != "name"]
    if unknown:
        extra = {"hold": " (hold, levels and delay are for inputs and disturbances)",
                 "preview": " (preview is for disturbances)",
                 "valid": " (valid, frozen and rate are for outputs and disturbances)",
                 "safe": " (safe is for inputs)"}.get(
            {"levels": "hold", "delay": "hold", "frozen": "valid", "rate": "valid"}.get(
                unknown[0], unknown[0]), "")
        raise ProblemFileError(f"{where(table, unknown[0])}: unknown key '{unknown[0]}' in "
                               f"[{kind}.{name}]{extra} (known: "
                               f"{', '.join(sorted(allowed - {'name'}))})")
    require(entry, ("unit", "min", "max"), where(table), f"[{kind}.{name}]")
    unit = text(entry["unit"], where(table, "unit"), "unit",
                hint=' (e.g. "m3/s", "K", "1" for none)')
    lo = number(entry["min"], where(table, "min"), "min")
    hi = number(entry["max"], where(table, "max"), "max")
    if not lo < hi:
        raise ProblemFileError(f"{where(table, 'max')}: [{kind}.{name}] needs min < max, got "
                               f"min = {lo:g}, max = {hi:g}")
    variable = entry.get("variable", name)
    if not isinstance(variable, str) or not variable:
        raise ProblemFileError(f"{where(table, 'variable')}: 'variable' must be the FMU "
                               "variable's name")
    description = text(entry.get("description", ""), where(table, "description"),
                       "description", empty=True)
    kw = {**_normalization(entry, where, table), **_excitation(entry, where, table, lo, hi),
          **_dynamics(entry, where, table, lo, hi), **_plausible(entry, where, table)}
    if "safe" in entry:
        safe = number(entry["safe"], where(table, "safe"), "safe")
        if not lo <= safe <= hi:
            raise ProblemFileError(f"{where(table, 'safe')}: 'safe' (the value written to a "
                                   f"live plant when its measurements stop) must be in the "
                                   f"box [{lo:g}, {hi:g}], got {safe:g}")
        kw["safe"] = safe
    kw.update(_operating(entry, where, table, lo, hi))
    return Channel(name=name, unit=unit, min=lo, max=hi, variable=variable,
                   description=description, **kw)


def _operating(entry: dict[str, Any], where: Where, table: str, lo: float, hi: float
               ) -> dict[str, float]:
    """An input's ``max_move`` and an output's ``limit_rate`` (problem units per sample, in
    ``(0, max − min]``) as keyword arguments (those given)."""
    kw: dict[str, float] = {}
    for key, what in (("max_move", "the largest move per sample"),
                      ("limit_rate", "how fast an operator limit narrows, per sample")):
        if key in entry:
            value = number(entry[key], where(table, key), key)
            if not 0 < value <= hi - lo:
                raise ProblemFileError(f"{where(table, key)}: '{key}' ({what}) must be in "
                                       f"(0, max - min = {hi - lo:g}], got {value:g}")
            kw[key] = value
    return kw


def _normalization(entry: dict[str, Any], where: Where, table: str) -> dict[str, float]:
    """A signal's ``normalization = { offset, scale }`` as keyword arguments (none when
    absent)."""
    norm = entry.get("normalization")
    if norm is None:
        return {}
    at = where(table, "normalization")
    if not isinstance(norm, dict):
        raise ProblemFileError(f"{at}: 'normalization' must be {{ offset = ..., scale = ... }}")
    bad = [k for k in norm if k not in _NORM]
    if bad or set(norm) != _NORM:
        raise ProblemFileError(f"{at}: 'normalization' takes exactly 'offset' and 'scale'")
    offset = number(norm["offset"], at, "normalization.offset")
    scale = number(norm["scale"], at, "normalization.scale")
    if scale == 0:
        raise ProblemFileError(f"{at}: 'normalization.scale' must not be 0")
    return {"offset": offset, "scale": scale}


def _excitation(entry: dict[str, Any], where: Where, table: str, lo: float, hi: float
                ) -> dict[str, tuple[Any, Any]]:
    """An input's data-generation ``hold`` (samples) and ``levels`` as keyword arguments
    (those given)."""
    kw: dict[str, tuple[Any, Any]] = {}
    if "hold" in entry:
        at = where(table, "hold")
        h0, h1 = pair(entry["hold"], at, "hold", integer=True)
        if not 1 <= h0 <= h1:
            raise ProblemFileError(f"{at}: 'hold' must satisfy 1 <= low <= high samples, got "
                                   f"[{h0:g}, {h1:g}]")
        kw["hold"] = (int(h0), int(h1))
    if "levels" in entry:
        at = where(table, "levels")
        l0, l1 = pair(entry["levels"], at, "levels")
        if not lo <= l0 < l1 <= hi:
            raise ProblemFileError(f"{at}: 'levels' must satisfy min <= low < high <= max "
                                   f"({lo:g}, {hi:g}), got [{l0:g}, {l1:g}]")
        kw["levels"] = (l0, l1)
    return kw


def _dynamics(entry: dict[str, Any], where: Where, table: str, lo: float, hi: float
              ) -> dict[str, Any]:
    """A signal's ``delay`` [samples], and a disturbance's ``rate`` and ``preview``, as
    keyword arguments (those given)."""
    kw: dict[str, Any] = {}
    if "delay" in entry:
        delay = entry["delay"]
        if (isinstance(delay, bool) or not isinstance(delay, int)
                or not 0 <= delay <= MAX_DELAY):
            raise ProblemFileError(f"{where(table, 'delay')}: 'delay' must be a whole number "
                                   f"of samples from 0 to {MAX_DELAY}, got {delay!r}")
        kw["delay"] = delay
    if "rate" in entry:
        rate = number(entry["rate"], where(table, "rate"), "rate")
        if not 0 < rate <= hi - lo:
            raise ProblemFileError(f"{where(table, 'rate')}: 'rate' (the largest change per "
                                   f"sample) must be in (0, max - min = {hi - lo:g}], got "
                                   f"{rate:g}")
        kw["rate"] = rate
    if "preview" in entry:
        if not isinstance(entry["preview"], bool):
            raise ProblemFileError(f"{where(table, 'preview')}: 'preview' must be true or "
                                   "false")
        kw["preview"] = entry["preview"]
    return kw


def _plausible(entry: dict[str, Any], where: Where, table: str) -> dict[str, Any]:
    """A measurement's ``valid`` range and ``frozen`` count as keyword arguments (those
    given): what a live run takes for a plausible value."""
    kw: dict[str, Any] = {}
    if "valid" in entry:
        at = where(table, "valid")
        lo, hi = pair(entry["valid"], at, "valid")
        if not lo < hi:
            raise ProblemFileError(f"{at}: 'valid' (the range a measurement can have) must "
                                   f"be [low, high] with low < high, got [{lo:g}, {hi:g}]")
        kw["valid"] = (lo, hi)
    if "frozen" in entry:
        n = entry["frozen"]
        if (isinstance(n, bool) or not isinstance(n, int) or n == 1
                or not 0 <= n <= MAX_FROZEN):
            raise ProblemFileError(f"{where(table, 'frozen')}: 'frozen' must be 0 (off) or a "
                                   f"whole number of samples from 2 to {MAX_FROZEN}, got {n!r}")
        kw["frozen"] = n
    return kw
