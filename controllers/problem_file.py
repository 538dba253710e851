"""Control-problem files (TOML): read and check them, one line naming the fault.

A problem file declares the plant's signals in its own names and units::

    [problem]
    name = "cstr"
    Ts = 15.0                      # controller sample time [s]
    description = "..."            # optional

    [inputs.F]                     # a manipulated input: the FMU input "F"
    unit = "L/min"
    min = 50.0
    max = 150.0
    variable = "F_in"              # optional: the FMU variable when it is named otherwise
    description = "feed flow"      # optional
    normalization = { offset = 100.0, scale = 50.0 }   # optional (default: the box)
    hold = [2, 40]                 # optional: excitation hold times [samples]
    levels = [60.0, 140.0]         # optional: excitation levels (default: the box)
    safe = 100.0                   # optional: written to a live plant by its watchdog
    max_move = 5.0                 # optional: largest move per sample (default: the box)

    [outputs.CA]                   # a measured, controlled output (eq:output-constraint)
    unit = "mol/L"
    min = 0.2
    max = 1.0
    valid = [0.0, 5.0]             # optional, live runs: the range a measurement can have
    rate = 0.3                     # optional, live runs: its largest change per sample
    frozen = 5                     # optional, live runs: the same to the bit for 5 samples
                                   #   is a frozen transmitter (noisy signals only)
    limit_rate = 0.01              # optional: how fast an operator limit narrows [/sample]

    [disturbances.Tin]             # optional: a measured disturbance (the FMU input or
    unit = "K"                     #   tunable parameter "Tin"), not moved by the controller
    min = 280.0
    max = 320.0
    rate = 0.5                     # optional: largest change per sample (default: the data's)
    preview = false                # optional: known ahead from the scenario (over dead time)
    delay = 2                      # optional, inputs too: dead time [samples]
    hold = [5, 80]                 # optional: its excitation in cosim generate-data
                                   # (valid and frozen as for an output)

    [pi]                           # optional: the PI baseline's loops (square plants)
    pairing = "main"
    [pi.pairings]
    main = [{ output = "CA", input = "F", K = -40.0, Ti = 300.0, Tt = 300.0 }]

    [train]                        # optional: how to identify this plant's model
    sigma_z_max = 0.9              # cosim train's options (cosim.commands.train)

    [mpc]                          # optional: the robust MPC's tuning for this plant
    Q = "outputs"                  # any robust-mpc option (controllers.mpc_options)
    R = 0.001

The ``[train]`` and ``[mpc]`` tables hold what was chosen for this plant: ``cosim train``'s
modelling options and the robust MPC's options (keys as ``--option``'s). They travel with the
problem into the data sidecar and the model file, and an option given on the command line
overrides them. Their keys are checked here for form only (names, TOML values); their meaning
and values by what takes them (:data:`cosim.commands.train.PROBLEM_OPTIONS`,
:meth:`controllers.mpc_options.MPCOptions.resolve`; errors located by :func:`locate_key`).

Every fault is a :class:`~controllers.errors.ProblemFileError` (exit 2) naming the file and
line: invalid TOML, an unknown key, a missing ``unit``/``min``/``max``/``Ts``/``name``,
``min ≥ max``, a non-finite number, a name used twice, a ``delay`` that is not a whole
number of samples in ``[0, MAX_DELAY]``, a ``rate`` not in ``(0, max − min]``, a ``safe``
value outside its box, a ``valid`` range that is not ``[low, high]``, a ``frozen`` count that
is not a whole number of samples, no inputs or no outputs, a bad loop.
Checks against a plant FMU (a signal it lacks, the wrong causality, a unit it contradicts)
belong to the co-simulation side (:mod:`cosim.core.binding`).
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path
from typing import Any

from controllers.errors import ProblemFileError
from controllers.problem import Channel, ControlProblem, PILoop
from controllers.problem_signals import (
    Where,
    channel,
    number,
    require,
    table_name,
    text,
)

__all__ = ["load", "loads", "locate", "locate_key", "problem_from_dict"]

_TOP = {"problem", "inputs", "outputs", "disturbances", "pi", "train", "mpc"}
_PROBLEM = {"name", "Ts", "description"}
#: The signal tables: the problem's attribute and JSON key; whether one is needed.
_KINDS = (("inputs", True), ("outputs", True), ("disturbances", False))
_PI = {"pairing", "pairings"}
_LOOP = {"output", "input", "K", "Ti", "Tt"}


class _Locator:
    """``file:line`` of keys in a TOML text (tomllib gives no positions)."""

    def __init__(self, path: str, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()

    def line(self, table: str, key: str | None) -> int:
        """Line of ``key`` in ``[table]`` (or of the header; of ``name = {...}`` in the
        parent table for an inline table)."""
        current, header = "", 0           # "": the top level, before any table
        for i, raw in enumerate(self.lines, start=1):
            s = raw.strip()
            m = re.match(r"^\[\s*([^\]]+?)\s*\]", s)
            if m:
                current = m.group(1).replace('"', "").replace(" ", "")
                header = i if current == table else header
                continue
            if current == table and key is not None:
                k = re.match(r'^("([^"]*)"|([A-Za-z0-9_-]+))\s*=', s)
                if k and (k.group(2) if k.group(2) is not None else k.group(3)) == key:
                    return i
        if header:
            return header
        parent, _, last = table.rpartition(".")
        if table:   # an inline table, or a top-level key (parent ""): where it is set
            return self.line(parent, last)
        return 1

    def __call__(self, table: str, key: str | None = None) -> str:
        return f"{self.path}:{self.line(table, key)}"


def load(path: str | Path) -> ControlProblem:
    """Read and check a problem file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ProblemFileError(f"{path}: cannot read the problem file "
                               f"({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise ProblemFileError(f"{path}: not a TOML problem file (byte {exc.start} is not "
                               "UTF-8)") from None
    return loads(text, str(path))


def loads(text: str, source: str = "<problem>") -> ControlProblem:
    """Check the text of a problem file (``source`` names it in messages)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        where = f"{source}:{m.group(1)}:{m.group(2)}" if m else source
        raise ProblemFileError(f"{where}: invalid TOML ({re.sub(r' ?[(]at .*[)]', '', msg)})"
                               ) from None
    loc = _Locator(source, text)
    _known(doc, _TOP, "the top level (tables: problem, inputs, outputs, disturbances, pi, "
           "train, mpc)", loc, "")
    channels = {}
    for kind, _needed in _KINDS:
        table = doc.get(kind, {})
        if not isinstance(table, dict):
            raise ProblemFileError(f"{loc(kind)}: '{kind}' must be tables [{kind}.NAME]")
        channels[kind] = [dict(v, name=k) if isinstance(v, dict) else v
                          for k, v in table.items()]
    flat = {"problem": doc.get("problem"), **channels, "pi": doc.get("pi"),
            "train": doc.get("train"), "mpc": doc.get("mpc")}

    def where(table: str, key: str | None = None) -> str:
        return loc(table, key)
    problem = _build(flat, where, toml=True)
    return _with_source(problem, source)


def problem_from_dict(doc: Any, source: str = "<problem>") -> ControlProblem:
    """A problem from its JSON form (:meth:`ControlProblem.to_dict`: channel lists)."""
    if not isinstance(doc, dict):
        raise ProblemFileError(f"{source}: 'problem' must be an object")
    flat = {"problem": {k: doc[k] for k in _PROBLEM if k in doc},
            "inputs": doc.get("inputs", []), "outputs": doc.get("outputs", []),
            "disturbances": doc.get("disturbances", []),
            "pi": doc.get("pi"), "train": doc.get("train"), "mpc": doc.get("mpc")}
    unknown = sorted(set(doc) - {*_PROBLEM, "inputs", "outputs", "disturbances", "pi", "train",
                                 "mpc"})
    if unknown:
        raise ProblemFileError(f"{source}: problem: unknown key '{unknown[0]}'")

    def where(table: str, key: str | None = None) -> str:
        return f"{source}: problem.{table}" + (f".{key}" if key else "")
    return _with_source(_build(flat, where, toml=False), source)


def locate(problem: ControlProblem, signal: str, key: str | None = None) -> str:
    """Where ``signal`` (or its ``key``, e.g. ``"unit"``) of ``problem`` is declared, for
    messages: ``file:line`` in a problem file (TOML), ``source: problem.inputs.F`` in a model
    file or data sidecar (the JSON form), ``<problem>: ...`` for a problem built in code.

    Raises
    ------
    KeyError
        ``signal`` is not an input, output or disturbance of ``problem``.
    """
    kinds = {**dict.fromkeys(problem.disturbance_names, "disturbances"),
             **dict.fromkeys(problem.output_names, "outputs"),
             **dict.fromkeys(problem.input_names, "inputs")}
    if signal not in kinds:
        raise KeyError(signal)
    kind = kinds[signal]
    return locate_key(problem, f"{kind}.{signal}", key)


def locate_key(problem: ControlProblem, table: str, key: str | None = None) -> str:
    """Where ``key`` of ``[table]`` of ``problem`` is declared (``"mpc"``, ``"R"``):
    ``file:line`` in a problem file, ``source: problem.mpc.R`` in the JSON form."""
    source = problem.source or "<problem>"
    path = Path(source)
    if path.suffix.lower() == ".toml":
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            return source
        return _Locator(source, text)(table, key)
    return f"{source}: problem.{table}" + (f".{key}" if key else "")


def _with_source(problem: ControlProblem, source: str) -> ControlProblem:
    object.__setattr__(problem, "source", source)
    return problem


# ---------------------------------------------------------------------------------------------
# Checks shared by the TOML and the JSON form
# ---------------------------------------------------------------------------------------------

def _known(table: dict, allowed: set[str], what: str, where: Any, name: str) -> None:
    unknown = [k for k in table if k not in allowed]
    if unknown:
        at = where(name, unknown[0]) if name else where(unknown[0], None)
        raise ProblemFileError(f"{at}: unknown key '{unknown[0]}' in {what} (known: "
                               f"{', '.join(sorted(allowed))})")


def _build(doc: dict[str, Any], where: Where, toml: bool) -> ControlProblem:
    head = doc.get("problem")
    if not isinstance(head, dict):
        raise ProblemFileError(f"{where('problem')}: no [problem] table (name, Ts)")
    if toml:
        _known(head, _PROBLEM, "[problem]", where, "problem")
    require(head, ("name", "Ts"), where("problem"), "[problem]")
    name = text(head["name"], where("problem", "name"), "name")
    Ts = number(head["Ts"], where("problem", "Ts"), "Ts")
    if Ts <= 0:
        raise ProblemFileError(f"{where('problem', 'Ts')}: 'Ts' must be positive [s], "
                               f"got {Ts:g}")
    description = text(head.get("description", ""), where("problem", "description"),
                       "description", empty=True)
    seen: dict[str, str] = {}
    kinds = {}
    for kind, needed in _KINDS:
        entries = doc.get(kind) or []
        if not isinstance(entries, list) or (needed and not entries):
            raise ProblemFileError(f"{where(kind)}: the problem has no {kind} "
                                   f"([{kind}.NAME] tables)")
        chans = []
        for i, entry in enumerate(entries):
            chans.append(channel(entry, kind, i, where, toml))
            c = chans[-1]
            for label, value in (("name", c.name), ("variable", c.variable)):
                other = seen.get(f"{label}:{value}")
                if other is not None:
                    raise ProblemFileError(f"{where(table_name(kind, c.name, i, toml))}: "
                                           f"{label} '{value}' is used twice ({other} and "
                                           f"{kind})")
                seen[f"{label}:{value}"] = kind
        kinds[kind] = tuple(chans)
    pairings, pairing = _pi(doc.get("pi"), kinds["inputs"], kinds["outputs"], where, toml)
    return ControlProblem(name=name, Ts=Ts, inputs=kinds["inputs"],
                          outputs=kinds["outputs"], disturbances=kinds["disturbances"],
                          pairings=pairings, pairing=pairing,
                          description=description, train=_options(doc, "train", where),
                          mpc=_options(doc, "mpc", where))


def _pi(doc: Any, inputs: tuple[Channel, ...], outputs: tuple[Channel, ...], where: Where,
        toml: bool) -> tuple[dict[str, tuple[PILoop, ...]], str]:
    if doc is None:
        return {}, ""
    at = where("pi")
    if not isinstance(doc, dict):
        raise ProblemFileError(f"{at}: [pi] must be a table (pairing, pairings)")
    bad = [k for k in doc if k not in _PI]
    if bad:
        raise ProblemFileError(f"{where('pi', bad[0])}: unknown key '{bad[0]}' in [pi] "
                               f"(known: {', '.join(sorted(_PI))})")
    sets = doc.get("pairings")
    if not isinstance(sets, dict) or not sets:
        raise ProblemFileError(f"{at}: [pi] needs 'pairings': named lists of loops "
                               "{ output, input, K, Ti, Tt }")
    pairings = {}
    in_names = [c.name for c in inputs]
    out_names = [c.name for c in outputs]
    for set_name, loops in sets.items():
        sat = where("pi.pairings", set_name)
        if not isinstance(loops, list) or not loops:
            raise ProblemFileError(f"{sat}: pairing '{set_name}' must be a list of loops")
        parsed = []
        for k, lp in enumerate(loops):
            if not isinstance(lp, dict):
                raise ProblemFileError(f"{sat}: loop {k} of '{set_name}' must be a table")
            bad = [key for key in lp if key not in _LOOP]
            missing = [key for key in ("output", "input", "K", "Ti") if key not in lp]
            if bad or missing:
                what = f"unknown key '{bad[0]}'" if bad else f"no '{missing[0]}'"
                raise ProblemFileError(f"{sat}: loop {k} of '{set_name}' has {what} (keys: "
                                       "output, input, K, Ti, Tt)")
            if lp["output"] not in out_names or lp["input"] not in in_names:
                raise ProblemFileError(f"{sat}: loop {k} of '{set_name}' pairs "
                                       f"{lp['output']!r} with {lp['input']!r}: not an output "
                                       f"({', '.join(out_names)}) and an input "
                                       f"({', '.join(in_names)})")
            K = number(lp["K"], sat, "K")
            Ti = number(lp["Ti"], sat, "Ti")
            Tt = number(lp.get("Tt", Ti), sat, "Tt")
            if K == 0 or Ti <= 0 or Tt <= 0:
                raise ProblemFileError(f"{sat}: loop {k} of '{set_name}' needs K != 0, "
                                       "Ti > 0 and Tt > 0 [s]")
            parsed.append(PILoop(lp["output"], lp["input"], K, Ti, Tt))
        for attr, label in (("y", "output"), ("u", "input")):
            names = [getattr(lp, attr) for lp in parsed]
            if len(set(names)) != len(names):
                raise ProblemFileError(f"{sat}: pairing '{set_name}' uses an {label} twice")
        pairings[set_name] = tuple(parsed)
    pairing = doc.get("pairing", next(iter(pairings)))
    if pairing not in pairings:
        raise ProblemFileError(f"{where('pi', 'pairing')}: pairing {pairing!r} is not one of "
                               f"{', '.join(pairings)}")
    return pairings, pairing


def _options(doc: dict[str, Any], table: str, where: Where) -> dict[str, Any]:
    """The ``[train]`` or ``[mpc]`` table: option names and plain values (checked by what
    takes them)."""
    options = doc.get(table)
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ProblemFileError(f"{where(table)}: [{table}] must be a table of options "
                               "(KEY = VALUE)")
    out = {}
    for key, value in options.items():
        if not key.isidentifier():
            raise ProblemFileError(f"{where(table, key)}: [{table}] key {key!r} is not an "
                                   "option name")
        out[key] = _plain(value, where(table, key), f"[{table}] '{key}'")
    return out


def _plain(value: Any, at: str, what: str) -> Any:
    """``value`` as JSON data (numbers, strings, booleans, lists, tables; not TOML dates)."""
    if isinstance(value, dict):
        return {str(k): _plain(v, at, what) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v, at, what) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        raise ProblemFileError(f"{at}: {what} must be finite, got {value!r}")
    if value is None or isinstance(value, bool | int | float | str):
        return value
    raise ProblemFileError(f"{at}: {what} must be a number, string, boolean, list or table, "
                           f"got {type(value).__name__}")
