"""One module per ``cosim`` sub-command; see :data:`cosim.cli.COMMANDS`. The arguments that
several commands share, with their help, are added here."""

from __future__ import annotations

import argparse

__all__ = ["add_design_arguments", "add_model_argument", "add_problem_argument"]

#: The help of a GRU model file argument.
MODEL_HELP = "GRU model file (default: the shipped controllers/models/fourtank_gru.json)"


def add_model_argument(p: argparse.ArgumentParser, flag: str | None = None,
                       metavar: str | None = None) -> None:
    """The GRU model file a command works on, the shipped model when not given: the optional
    positional ``model``, or the option ``flag`` (``--model``)."""
    if flag is None:
        p.add_argument("model", metavar=metavar, nargs="?", default=None, help=MODEL_HELP)
    else:
        p.add_argument(flag, metavar=metavar, default=None, help=MODEL_HELP)


def add_problem_argument(p: argparse.ArgumentParser) -> None:
    """``--problem`` of a command that works on a model file: checked against the model's
    own, or the problem of a model file without one."""
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="control problem file: must agree with the model's own (checked), or "
                        "gives the problem of a model file without one")


def add_design_arguments(p: argparse.ArgumentParser, option_help: str) -> None:
    """``--problem`` and ``--option`` of the commands that build the robust MPC of a model
    file (``build-kernel``, ``export-fmu``), with ``option_help`` for ``--option``."""
    add_problem_argument(p)
    p.add_argument("--option", metavar="KEY=VALUE", action="append", default=[],
                   help=option_help)
