"""Errors the user can act on, and the exit codes of the ``cosim`` command line.

Every error raised for bad user input (scenario files, variable maps, model files, FMUs)
is a :class:`CosimError` whose message is one line naming the file and line/column or the
variable at fault. The CLI prints it without a traceback and exits non-zero.

The exit codes and what they mean are defined here once, in :data:`EXIT_CODES`;
:func:`exit_codes_help` renders them (with what a code also means for one command) for
``cosim --help`` and every ``cosim <command> --help``.
"""

from __future__ import annotations

import textwrap
import unicodedata
from collections.abc import Mapping

__all__ = [
    "EXIT_CODES",
    "EXIT_FAILED",
    "EXIT_INPUT_ERROR",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_SIGNAL_BASE",
    "CosimError",
    "FmuError",
    "OutputError",
    "ParameterError",
    "SimulationFailed",
    "exit_codes_help",
    "one_line",
]


#: Unicode categories a message shows escaped: control and format characters (an escape
#: sequence, a bidirectional override), line and paragraph separators.
_ESCAPED = frozenset({"Cc", "Cf", "Zl", "Zp"})
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def one_line(text: str) -> str:
    """``text`` as one line a terminal shows as it is: every control or format character
    (a line break, an escape sequence from a file or an FMU) written as its escape.

    >>> one_line("sc.csv:3:2: '0.6\\n1' and '\\x1b[31m'")
    "sc.csv:3:2: '0.6\\\\n1' and '\\\\x1b[31m'"
    """
    if text.isascii() and text.isprintable():
        return text
    out = []
    for ch in text:
        if ch in _NAMED:
            out.append(_NAMED[ch])
        elif unicodedata.category(ch) in _ESCAPED:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"
                       if code < 0x10000 else f"\\U{code:08x}")
        else:
            out.append(ch)
    return "".join(out)


class CosimError(Exception):
    """A one-line, user-facing error (bad input, invalid configuration).

    The CLI maps it to exit code 2 (:data:`EXIT_INPUT_ERROR`).
    """


class SimulationFailed(CosimError):
    """A run that started but could not finish (FMU error or crash, solver breakdown).

    Results computed up to the fault are kept on disk. The CLI maps it to exit code 1
    (:data:`EXIT_FAILED`).
    """


class ParameterError(CosimError):
    """A bad value of a named parameter of the library (``seed``, ``step``, ...).

    The message starts with the parameter's Python name; the command layer, which knows its
    flags, rewrites it as the option (:meth:`as_option`: ``--step-timeout ...``).
    """

    def __init__(self, parameter: str, detail: str) -> None:
        super().__init__(f"{parameter}{detail}")
        self.parameter = parameter
        self.detail = detail

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        """Pickled as its arguments (raised in a worker process, re-raised in the parent)."""
        return (ParameterError, (self.parameter, self.detail))

    def as_option(self) -> CosimError:
        """The same error worded for the command line: ``--<parameter>`` with dashes."""
        return CosimError(f"--{self.parameter.replace('_', '-')}{self.detail}")


class FmuError(SimulationFailed):
    """An FMU call that failed during a run, with the FMI status it returned (if any).

    Parameters
    ----------
    message : str
        The one-line message.
    function : str
        The FMI function that failed (``"fmi2DoStep"``), or ``""`` when the failure was not
        a status returned by the FMU (a termination request, a crash of the wrapper).
    status : int, optional
        Its FMI status: 2 discard, 3 error, 4 fatal (FMI 2 and 3 number them alike).
    """

    #: The FMI status "fatal": the FMU instance is unusable and must not even be freed.
    FATAL = 4

    def __init__(self, message: str, function: str = "", status: int | None = None) -> None:
        super().__init__(message)
        self.function = function
        self.status = status

    def __reduce__(self) -> tuple[type, tuple[str, str, int | None]]:
        """Pickled with the FMI function and status (a worker's failure keeps them)."""
        return (FmuError, (str(self), self.function, self.status))

    @property
    def fatal(self) -> bool:
        """Whether the FMU returned the status fatal."""
        return self.status == self.FATAL


class OutputError(SimulationFailed):
    """An output file could not be written (full disk, unwritable target).

    The message names the file; the previous content of that file, if any, is intact
    (see :mod:`cosim.core.atomicio`). The CLI maps it to exit code 1 (:data:`EXIT_FAILED`).
    """


#: The command did what was asked.
EXIT_OK = 0
#: A run failed mid-way (partial results kept), an output file could not be written, or the
#: command's check failed (``compare`` found a deviation, ``certify`` a failed hypothesis).
EXIT_FAILED = 1
#: Bad input or usage: nothing was run.
EXIT_INPUT_ERROR = 2
#: Interrupted by the user (Ctrl-C, SIGINT); any signal N gives ``EXIT_SIGNAL_BASE + N``.
EXIT_INTERRUPTED = 130
#: Stopped by signal N (SIGINT, SIGTERM, SIGHUP): exit status ``128 + N`` (130, 143, 129).
EXIT_SIGNAL_BASE = 128

#: Every exit code of ``cosim`` and what it means for any command, in ``--help`` order.
#: A command adds what a code also means for it with :func:`exit_codes_help`.
EXIT_CODES: tuple[tuple[int, str], ...] = (
    (EXIT_OK, "success"),
    (EXIT_FAILED, "a run failed mid-way (partial results kept), or an output file could not "
                  "be written (its previous content is kept)"),
    (EXIT_INPUT_ERROR, "bad input or usage (file:line:column where it applies); nothing was "
                       "run"),
    (EXIT_INTERRUPTED, "interrupted by Ctrl-C (SIGINT); 143 by SIGTERM, 129 by SIGHUP "
                       "(partial results kept)"),
)


def exit_codes_help(notes: Mapping[str, Mapping[int, str]] | None = None,
                    width: int = 92) -> str:
    """The ``exit codes:`` paragraph of a ``--help`` epilog, rendered from :data:`EXIT_CODES`.

    Parameters
    ----------
    notes : mapping, optional
        Command name → {exit code: what the code also means for that command}; each note is
        printed under the code's meaning as ``<command>: <note>``.
    width : int
        Longest line.

    Returns
    -------
    str
        ``"exit codes:"`` then one entry per code (wrapped, indented), no final newline.

    Examples
    --------
    >>> print(exit_codes_help({"compare": {1: "a signal outside the tolerance band"}}))
    ... # doctest: +NORMALIZE_WHITESPACE +ELLIPSIS
    exit codes:
      0    success
      1    a run failed mid-way (partial results kept), or an output file could not be ...
           compare: a signal outside the tolerance band
    ...
    """
    indent = " " * 7
    lines = ["exit codes:"]
    for code, meaning in EXIT_CODES:
        entry = textwrap.wrap(meaning, width, initial_indent=f"  {code:<4} ",
                              subsequent_indent=indent)
        for command, extra in (notes or {}).items():
            if code in extra:
                entry += textwrap.wrap(f"{command}: {extra[code]}", width,
                                       initial_indent=indent, subsequent_indent=indent + "  ")
        lines += entry
    return "\n".join(lines)
