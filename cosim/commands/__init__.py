"""One module per ``cosim`` sub-command; see :data:`cosim.cli.COMMANDS`. The arguments that
several commands share, with their help, are added here."""

from __future__ import annotations

import argparse

__all__ = ["add_design_arguments", "add_hmi_arguments", "add_model_argument",
           "add_problem_argument", "hmi_options"]

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


def add_hmi_arguments(p: argparse.ArgumentParser, what: str, default: str | None = None) -> None:
    """``--hmi [HOST:]PORT`` and ``--hmi-users FILE``: where ``what`` (a run's page, a
    campaign's) is served and who may operate it (:mod:`cosim.hmi`); ``default``: the
    address without ``--hmi`` (``None``: no page)."""
    when = f"default {default}" if default else "default: no page"
    p.add_argument("--hmi", metavar="[HOST:]PORT", default=default,
                   help=f"serve {what} in a web browser at http://HOST:PORT/ (HOST "
                        f"127.0.0.1 unless given; {when}); updates are pushed, every script "
                        "is served by cosim itself")
    p.add_argument("--hmi-users", metavar="USERS.toml", default=None,
                   help="who may log in to operate the page: names, roles (operator, "
                        "engineer) and password hashes (python -m cosim.hmi.users writes "
                        "them); viewing on 127.0.0.1 needs no login, any other host does")


def hmi_options(args: argparse.Namespace) -> object:
    """The page's options of ``--hmi`` and ``--hmi-users`` (``None`` without a page).

    Raises
    ------
    CosimError
        A bad address or users file, or ``--hmi-users`` without ``--hmi``.
    """
    from cosim.core.errors import CosimError

    if args.hmi is None:
        if args.hmi_users is not None:
            raise CosimError("--hmi-users: only with --hmi (the page it logs in to)")
        return None
    from cosim.hmi.serving import HmiOptions

    return HmiOptions.parse(args.hmi, args.hmi_users)
