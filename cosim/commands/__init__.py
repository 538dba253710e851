"""One module per ``cosim`` sub-command; see :data:`cosim.cli.COMMANDS`."""

from __future__ import annotations

import argparse

__all__ = ["add_design_arguments"]


def add_design_arguments(p: argparse.ArgumentParser, option_help: str) -> None:
    """``--problem`` and ``--option`` of the commands that build the robust MPC of a model
    file (``build-kernel``, ``export-fmu``), with ``option_help`` for ``--option``."""
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="control problem file: must agree with the model's own (checked), or "
                        "gives the problem of a model file without one")
    p.add_argument("--option", metavar="KEY=VALUE", action="append", default=[],
                   help=option_help)
