"""Which control problem a run, a controller or a command works with.

A problem file (:mod:`controllers.problem_file`) travels with the model trained for it: the
model file holds it (:attr:`controllers.model.GRUModel.problem`). The rules, the same for
every command and controller:

- a model with a problem: that problem; a ``--problem`` given as well must be the same
  (otherwise one line naming both and what differs, exit 2), but for its ``[mpc]`` table
  (the robust MPC's tuning, which may change after training): the given one's, when it
  has one, is used;
- a model without one (written before problems existed): the ``--problem`` given, or the
  default plant's, checked against the model's signals, sample time and normalisation;
- no model (the PI baseline, ``generate-data``): the ``--problem`` given, or the default
  plant's: the four-tank's ``fmus/fourtank/problem.toml``
  (:data:`cosim.core.build.DEFAULT_PROBLEM`).

:func:`bind_plant` binds a problem to a plant FMU (:mod:`cosim.core.binding`: names, units,
checks) and gives the variable map the FMU component converts through.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from controllers.errors import ControllersError
from controllers.problem import ControlProblem
from cosim.core.errors import CosimError

__all__ = ["bind_plant", "default_problem_path", "load_problem", "plant_signals",
           "problem_for"]


def default_problem_path() -> Path:
    """The default plant's problem file (the four-tank's)."""
    from cosim.core.build import DEFAULT_PROBLEM

    return DEFAULT_PROBLEM


def load_problem(arg: str | Path | ControlProblem | None) -> ControlProblem:
    """``arg`` as a problem: itself, or the file it names, or the default plant's.

    Raises
    ------
    CosimError
        The file is missing or malformed (one line naming the file and line).
    """
    if isinstance(arg, ControlProblem):
        return arg
    if arg is not None and not isinstance(arg, str | Path):
        raise CosimError(f"problem={arg!r}: expected the path of a problem file (TOML)")
    from controllers.problem_file import load

    path = Path(arg) if arg is not None else default_problem_path()
    if arg is not None and not path.is_file():
        raise CosimError(f"{path}: problem file not found")
    try:
        return load(path)
    except ControllersError as exc:
        raise CosimError(str(exc)) from None


def problem_for(model: Any, arg: str | Path | ControlProblem | None = None) -> ControlProblem:
    """The problem of ``model`` (a :class:`controllers.model.GRUModel`, or ``None``) given a
    ``--problem`` argument ``arg`` (see the module docstring).

    Raises
    ------
    CosimError
        ``arg`` contradicts the model's problem, or no problem fits the model.
    """
    own = getattr(model, "problem", None) if model is not None else None
    if own is not None:
        if arg is not None:
            given = load_problem(arg)
            diff = own.differences(given)
            if diff:
                raise CosimError(f"{_name(arg, given)} contradicts the problem of "
                                 f"{model.source or 'the model'} ({own.name!r}): "
                                 f"{'; '.join(diff[:3])}")
            operating = _operating(own, given)
            if given.mpc and given.mpc != own.mpc:   # the tuning, located in the given file
                return dataclasses.replace(operating, mpc=dict(given.mpc),
                                           source=given.source)
            return operating
        return own
    problem = load_problem(arg)
    if model is not None:
        bad = model.mismatch(problem)
        if bad:
            where = model.source or "the model"
            hint = "" if arg is not None else " (it has no problem of its own: give --problem)"
            raise CosimError(f"{_name(arg, problem)} does not fit {where}{hint}: {bad}")
    return problem


def _operating(own: ControlProblem, given: ControlProblem) -> ControlProblem:
    """``own`` with the operating limits of ``given`` (inputs' ``max_move``, outputs'
    ``limit_rate``), which, like the ``[mpc]`` tuning, may change after training."""
    def merged(a: tuple, b: tuple, key: str) -> tuple:
        return tuple(dataclasses.replace(ca, **{key: getattr(cb, key)})
                     for ca, cb in zip(a, b, strict=True))

    inputs = merged(own.inputs, given.inputs, "max_move")
    outputs = merged(own.outputs, given.outputs, "limit_rate")
    if inputs == own.inputs and outputs == own.outputs:
        return own
    return dataclasses.replace(own, inputs=inputs, outputs=outputs, source=given.source)


def _name(arg: Any, problem: ControlProblem) -> str:
    if arg is None:
        return f"the default problem {problem.source or problem.name}"
    if isinstance(arg, ControlProblem):
        return f"problem {arg.name!r}"
    return f"--problem {arg}"


def plant_signals(problem: ControlProblem) -> list[Any]:
    """The problem's inputs, outputs and measured disturbances (written into the FMU like
    inputs) as :class:`cosim.core.binding.Wanted` (plain data), each
    with where it is declared (``problem.toml:12``, :func:`controllers.problem_file.locate`)."""
    from controllers.problem_file import locate
    from cosim.core.binding import Wanted

    out = []
    for role, channels in (("input", problem.inputs), ("output", problem.outputs),
                           ("disturbance", problem.disturbances)):
        for c in channels:
            key = "variable" if c.variable != c.name else None
            out.append(Wanted(c.name, c.variable, c.unit, role, locate(problem, c.name, key),
                              locate(problem, c.name, "unit")))
    return out


def bind_plant(problem: ControlProblem, fmu: str | Path, user_map: Any = None) -> Any:
    """The :class:`~cosim.core.varmap.VarMap` binding ``problem`` to the plant FMU ``fmu`` (a
    ``--map`` ``user_map`` first): :func:`cosim.core.binding.bind`.

    Raises
    ------
    CosimError
        The FMU cannot be read; a signal it lacks, of the wrong causality or type, or in a unit
        it contradicts (one line naming the problem file and line, the signal, the variable).
    """
    from cosim.core.binding import bind
    from cosim.core.fmu_archive import read_model_description

    md = read_model_description(fmu)
    return bind(plant_signals(problem), md, fmu, user_map, problem.source or problem.name)
