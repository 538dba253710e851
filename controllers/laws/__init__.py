"""The control laws of the robust MPC, one registered spec each.

A law is one folder of this package (``controllers/laws/<name>/``) that owns everything that
differs between laws: its name, its defaults and options, its reference of the FHOCP
(``eq:optimization``'s pluggable part, :class:`controllers.ocp.reference.Reference`), its
step (a :class:`~controllers.laws.base.ControlLaw`), the hypotheses ``cosim certify`` checks,
its C source and what the controller FMU exports. Its ``__init__`` module declares it in a
:class:`LawSpec` named ``SPEC``; :func:`spec` finds a law by its name, the same name in
Python, in C (``controllers/laws/<name>/*.c``), on the command line (``--option
'law="<name>"'``, ``cosim certify --law <name>``) and in the docs. The folder's modules
implement it, each with the same functions (:meth:`LawSpec.hook`):

``law.py``
    ``build(context) -> (law, failures)``: the law (a :class:`~controllers.laws.base.
    ControlLaw`) of a design (:class:`~controllers.laws.base.LawContext`) and its hypotheses
    that fail, in words.
``certify.py``
    ``certify(model, cert, kwargs, setpoints, failures, n_design, no_theta)``: its
    hypotheses for ``cosim certify`` (:class:`~controllers.laws.base.Certified`).
``export.py``
    ``export_design(law, observer, model, u_lo, u_hi)`` (the C step's numbers,
    :class:`controllers.kernel.controller_source.ControllerDesign`), ``title(law)``,
    ``parameters(design, inputs, outputs)`` and ``parameter_count(design)`` (its tunable
    parameters, the settings of :meth:`controllers.mpc.RobustMPC.set`) and
    ``c_switches(design)`` (its ``#define`` lines).

The built-in laws: ``"tracking"`` (the default: MPC for tracking with an artificial steady
state, :mod:`controllers.laws.tracking`) and ``"paper"`` (the paper's regulation law
``eq:mpc`` with its reference governor, :mod:`controllers.laws.paper`). A law of one's own is
a package with a ``SPEC`` of the same shape, named by its module path (``law =
"mypackage.mylaw"``) or registered with :func:`register`; nothing outside its folder changes
(docs: guide/contributing.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from controllers.errors import OptionError

__all__ = ["BUILTIN", "DEFAULT", "REFERENCE", "LawSpec", "Option", "known", "register", "spec"]

#: The laws of this package, by name (their ``SPEC`` is imported when first asked for).
BUILTIN: dict[str, str] = {"tracking": "controllers.laws.tracking",
                           "paper": "controllers.laws.paper"}
#: The law a design without ``law`` runs.
DEFAULT = "tracking"
#: The law whose certificate is the paper's theorem as written (``eq:mpc``, its section V
#: design): what "certified" means where no law is named (a campaign's drawn set-points).
REFERENCE = "paper"


@dataclass(frozen=True)
class Option:
    """An option only one law takes: its ``name``, its ``default`` under that law, why a
    value is refused (``check(value)``: a phrase, ``None`` when it is fine) and the values
    that mean "not used" (``off``), which every other law accepts."""

    name: str
    default: Any = None
    check: Callable[[Any], str | None] = lambda value: None
    off: tuple[Any, ...] = (None,)


@dataclass(frozen=True)
class LawSpec:
    """A control law, declared once (module docstring).

    Attributes
    ----------
    name : str
        Its name everywhere (``law = "<name>"``).
    title : str
        How a sentence names it (``"tracking law"``, ``"paper's law"``).
    defaults : mapping
        The defaults it gives the design numbers every law has
        (:class:`controllers.mpc_options.MPCOptions`: ``N``, ``max_iter``, ``offset_filter``,
        ``du_weight``).
    options : tuple of Option
        The options only it takes.
    foreign_note : str
        Why it refuses another law's option (said after the option's owner).
    package : str
        The package of its folder (its modules: the module docstring).
    c_sources : tuple of Path
        Its C files, joined in this order after ``controllers/kernel/controller.h``
        (:mod:`controllers.kernel.controller_source`).
    """

    name: str
    title: str
    defaults: Mapping[str, Any]
    options: tuple[Option, ...] = ()
    foreign_note: str = ""
    package: str = ""
    c_sources: tuple[Path, ...] = field(default_factory=tuple)

    @property
    def option_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.options)

    def option(self, name: str) -> Option:
        """Its option ``name``."""
        return next(o for o in self.options if o.name == name)

    def hook(self, module: str, function: str) -> Callable[..., Any]:
        """Its function ``function`` of its folder's module ``module`` (imported on first
        use)."""
        return getattr(importlib.import_module(f"{self.package}.{module}"), function)


_REGISTERED: dict[str, LawSpec] = {}


def register(law: LawSpec) -> LawSpec:
    """Make ``law`` known by its name (returns it)."""
    _REGISTERED[law.name] = law
    return law


def known() -> tuple[str, ...]:
    """The names of the built-in and registered laws."""
    return tuple(sorted({*BUILTIN, *_REGISTERED}))


def spec(name: Any) -> LawSpec:
    """The law named ``name``: a built-in or registered law, else a module exposing a
    ``SPEC`` (``"mypackage.mylaw"``), registered then under its spec's name.

    Raises
    ------
    OptionError
        No such law, in one line naming the known ones.
    """
    if isinstance(name, str) and name in _REGISTERED:
        return _REGISTERED[name]
    module: ModuleType | None = None
    if isinstance(name, str) and name:
        path = BUILTIN.get(name, name)
        try:
            module = importlib.import_module(path)
        except ImportError:
            module = None
    law = getattr(module, "SPEC", None)
    if not isinstance(law, LawSpec) or (name in BUILTIN and law.name != name):
        raise OptionError(f"option law={name!r}: expected one of "
                          f"{', '.join(map(repr, known()))} (or the module of a law's spec)")
    return register(law)
