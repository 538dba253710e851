"""Which control problem a run, a controller or a command works with.

A problem file (:mod:`controllers.problem_file`) travels with the model trained for it: the
model file holds it (:attr:`controllers.model.GRUModel.problem`). The rules, the same for
every command and controller:

- a model with a problem: that problem; a ``--problem`` given as well must be the same
  (otherwise one line naming both and what differs, exit 2);
- a model without one (written before problems existed): the ``--problem`` given, or the
  default plant's, checked against the model's signals, sample time and normalisation;
- no model (the PI baseline, ``generate-data``): the ``--problem`` given, or the default
  plant's: the four-tank's ``fmus/fourtank/problem.toml`` (:data:`cosim.build.DEFAULT_PROBLEM`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from controllers.errors import ControllersError
from controllers.problem import ControlProblem
from cosim.errors import CosimError

__all__ = ["default_problem_path", "load_problem", "problem_for"]


def default_problem_path() -> Path:
    """The default plant's problem file (the four-tank's)."""
    from cosim.build import DEFAULT_PROBLEM

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
        return own
    problem = load_problem(arg)
    if model is not None:
        bad = model.mismatch(problem)
        if bad:
            where = model.source or "the model"
            hint = "" if arg is not None else " (it has no problem of its own: give --problem)"
            raise CosimError(f"{_name(arg, problem)} does not fit {where}{hint}: {bad}")
    return problem


def _name(arg: Any, problem: ControlProblem) -> str:
    if arg is None:
        return f"the default problem {problem.source or problem.name}"
    if isinstance(arg, ControlProblem):
        return f"problem {arg.name!r}"
    return f"--problem {arg}"
