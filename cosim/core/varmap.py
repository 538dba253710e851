"""Variable maps: the project's signal names onto a third-party FMU's variables.

A map is a TOML file with one table per project signal::

    [signals.qa]
    variable = "Fa"        # the FMU's variable name (required)
    unit = "l/min"         # the unit the FMU declares for it (checked when both declare one)
    scale = 60000.0        # plant_value = scale * project_value + offset
    offset = 0.0

Inputs are converted on the way into the FMU (``plant = scale * project + offset``) and
outputs the inverse way out (``project = (plant - offset) / scale``). Signals that a map does
not name are looked up in the FMU under their own name. A run binds its control problem to
the FMU through :mod:`cosim.core.binding`, where a map takes precedence over the problem's own
``variable`` keys (an entry without ``scale`` and ``offset`` only renames: the units then
decide the conversion).

Before the first step :meth:`VarMap.check` holds the map against the FMU's
modelDescription: a missing variable, a wrong causality or a unit mismatch is a one-line
:class:`~cosim.core.errors.CosimError` naming the map file, the signal and the variable. Every
entry is checked, including those the run does not use.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from cosim.core.errors import CosimError

__all__ = ["Affine", "MappedSignal", "VarMap", "load", "variable_unit"]

_KEYS = {"variable", "unit", "scale", "offset"}
#: Causalities a map entry may point at (what a run sets or reads).
_MAPPABLE = ("input", "output", "parameter")
#: fmpy's type names of real-valued variables (FMI 2.0, FMI 3.0).
_REAL_TYPES = ("Real", "Float64")


class Affine:
    """``plant_value = scale * project_value + offset``: a map entry's and a live tag's
    conversion (the class defines ``scale`` and ``offset``)."""

    scale: float
    offset: float

    def to_plant(self, value: float) -> float:
        """Project value → the plant's value."""
        return self.scale * value + self.offset

    def from_plant(self, value: float) -> float:
        """The plant's value → project value."""
        return (value - self.offset) / self.scale


@dataclass(frozen=True)
class MappedSignal(Affine):
    """One project signal mapped onto an FMU variable (affine unit conversion)."""

    signal: str
    variable: str
    unit: str | None = None
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class VarMap:
    """A parsed variable map (see the module docstring for the file format)."""

    path: Path
    signals: Mapping[str, MappedSignal]

    @classmethod
    def identity(cls) -> VarMap:
        """The map used when none is given: every signal keeps its name and unit."""
        return cls(path=Path("<no map>"), signals={})

    def lookup(self, signal: str) -> MappedSignal:
        """The mapping of ``signal`` (identity when the map does not name it)."""
        return self.signals.get(signal) or MappedSignal(signal, signal)

    def signal_of(self, variable: str) -> str:
        """The project name of an FMU variable (itself when no map entry points at it)."""
        for m in self.signals.values():
            if m.variable == variable:
                return m.signal
        return variable

    def check(
        self,
        model_variables: Mapping[str, object],
        inputs: Iterable[str],
        outputs: Iterable[str],
        units: Mapping[str, str] | None = None,
        fmu: str = "FMU",
    ) -> None:
        """Check the signals a run needs against the FMU's variables.

        Parameters
        ----------
        model_variables : mapping
            FMU variable name → fmpy ``ModelVariable`` (``causality``, ``unit``,
            ``declaredType``).
        inputs : iterable of str
            Project signals the run writes into the plant (controller outputs).
        outputs : iterable of str
            Project signals the run reads from the plant (measured outputs).
        units : mapping, optional
            Project signal → project unit, used when a map entry declares no unit and the
            mapping is the identity.
        fmu : str
            The FMU file, named in errors about signals the map does not mention.

        Every entry of the map is checked too, whether the run uses its signal or not (a
        typo in an entry the scenario does not use would otherwise go unnoticed, or rename a
        recorded column): its variable must exist, be a real-valued input, output or
        parameter of the FMU, and have the unit the entry declares.

        Raises
        ------
        CosimError
            ``MAP: signal 'qa' -> variable 'Fa': ...`` on the first problem found (the
            signals the run uses first, then the other map entries in file order).
        """
        units = units or {}
        for signals, causality in ((inputs, "input"), (outputs, "output")):
            for signal in signals:
                m = self.lookup(signal)
                if signal in self.signals:
                    where = f"{self.path}: signal '{signal}' -> variable '{m.variable}'"
                else:
                    where = f"{fmu}: signal '{signal}' (not in a variable map)"
                var = model_variables.get(m.variable)
                if var is None:
                    hint = "" if signal in self.signals else " (map it with --map)"
                    raise CosimError(f"{where}: the FMU has no such variable{hint}")
                actual = getattr(var, "causality", None)
                tunable = (causality == "input" and actual == "parameter"
                           and getattr(var, "variability", None) == "tunable")
                if actual != causality and not tunable:
                    role = ("a controller output must drive an FMU input (or a tunable "
                            "parameter)" if causality == "input"
                            else "a measured signal must be an FMU output")
                    raise CosimError(f"{where}: causality is '{actual}', {role}")
                fmu_unit = variable_unit(var)
                expected = m.unit
                if expected is None and m.scale == 1.0 and m.offset == 0.0:
                    expected = units.get(signal)
                if expected and fmu_unit and expected != fmu_unit:
                    who = "the map" if m.unit else "the controller"
                    raise CosimError(f"{where}: unit mismatch: {who} expects '{expected}', "
                                     f"the FMU declares '{fmu_unit}'")
        self.check_entries(model_variables)

    def check_entries(self, model_variables: Mapping[str, object]) -> None:
        """Check every entry of the map on its own (in file order): its variable must exist,
        be a real-valued input, output or parameter of the FMU, and have the unit the entry
        declares.

        Raises
        ------
        CosimError
            ``MAP: signal 'qa' -> variable 'Fa': ...`` on the first problem found.
        """
        for m in self.signals.values():
            self._check_entry(m, model_variables)

    def _check_entry(self, m: MappedSignal, model_variables: Mapping[str, object]) -> None:
        """Check one map entry on its own: variable, causality, type and unit."""
        where = f"{self.path}: signal '{m.signal}' -> variable '{m.variable}'"
        var = model_variables.get(m.variable)
        if var is None:
            raise CosimError(f"{where}: the FMU has no such variable")
        causality = getattr(var, "causality", None)
        if causality not in _MAPPABLE:
            raise CosimError(f"{where}: causality is '{causality}'; a map entry must name an "
                             "FMU input, output or parameter")
        kind = getattr(var, "type", None)
        if kind is not None and kind not in _REAL_TYPES:
            raise CosimError(f"{where}: the variable is of type '{kind}'; only real-valued "
                             "variables can be mapped")
        fmu_unit = variable_unit(var)
        if m.unit and fmu_unit and m.unit != fmu_unit:
            raise CosimError(f"{where}: unit mismatch: the map expects '{m.unit}', the FMU "
                             f"declares '{fmu_unit}'")


def variable_unit(var: object) -> str | None:
    """The unit an fmpy ``ModelVariable`` declares, directly or through its declared type."""
    unit = getattr(var, "unit", None)
    if unit:
        return unit
    declared = getattr(var, "declaredType", None)
    return getattr(declared, "unit", None) or None


def load(path: str | Path) -> VarMap:
    """Read a variable map TOML file.

    Raises
    ------
    CosimError
        One line naming the file (and the line/column for TOML syntax errors, or the signal
        for a bad entry).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CosimError(f"{path}: variable map not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise CosimError(f"{path}: invalid TOML: {exc}") from None
    except RecursionError:
        raise CosimError(f"{path}: invalid TOML: nested too deeply") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CosimError(f"{path}: cannot read variable map: {exc}") from None

    extra = set(data) - {"signals", "plant", "description"}
    if extra:
        raise CosimError(f"{path}: unknown top-level key(s) {sorted(extra)}; expected [signals.*]")
    table = data.get("signals")
    if not isinstance(table, dict) or not table:
        raise CosimError(f"{path}: no [signals.<name>] tables")
    signals: dict[str, MappedSignal] = {}
    variables: dict[str, str] = {}
    for name, entry in table.items():
        where = f"{path}: signal '{name}'"
        if not isinstance(entry, dict):
            raise CosimError(f"{where}: expected a table [signals.{name}]")
        unknown = set(entry) - _KEYS
        if unknown:
            raise CosimError(f"{where}: unknown key(s) {sorted(unknown)}; "
                             f"allowed: {sorted(_KEYS)}")
        variable = entry.get("variable")
        if variable is None:
            raise CosimError(f"{where}: 'variable' (the FMU variable name) is missing")
        if not isinstance(variable, str) or not variable:
            raise CosimError(f"{where}: 'variable' must be the FMU variable name as a "
                             f"non-empty string, got {variable!r}")
        if variable in variables:
            raise CosimError(f"{where}: variable '{variable}' is already mapped by signal "
                             f"'{variables[variable]}'")
        variables[variable] = name
        unit = entry.get("unit")
        if unit is not None and not isinstance(unit, str):
            raise CosimError(f"{where}: 'unit' must be a string")
        nums = {}
        for key, default in (("scale", 1.0), ("offset", 0.0)):
            value = entry.get(key, default)
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not math.isfinite(value):
                raise CosimError(f"{where}: '{key}' must be a finite number")
            nums[key] = float(value)
        if nums["scale"] == 0.0:
            raise CosimError(f"{where}: 'scale' must not be zero")
        signals[name] = MappedSignal(name, variable, unit or None, nums["scale"], nums["offset"])
    return VarMap(path=path, signals=signals)
