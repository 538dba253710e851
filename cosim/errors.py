"""Errors the user can act on.

Every error raised for bad user input (scenario files, variable maps, model files, FMUs)
is a :class:`CosimError` whose message is one line naming the file and line/column or the
variable at fault. The CLI prints it without a traceback and exits non-zero.
"""

from __future__ import annotations


class CosimError(Exception):
    """A one-line, user-facing error (bad input, invalid configuration).

    The CLI maps it to exit code 2 (:data:`EXIT_INPUT_ERROR`).
    """


class SimulationFailed(CosimError):
    """A run that started but could not finish (FMU error or crash, solver breakdown).

    Results computed up to the fault are kept on disk. The CLI maps it to exit code 1
    (:data:`EXIT_FAILED`).
    """


class OutputError(SimulationFailed):
    """An output file could not be written (full disk, unwritable target).

    The message names the file; the previous content of that file, if any, is intact
    (see :mod:`cosim.atomicio`). The CLI maps it to exit code 1 (:data:`EXIT_FAILED`).
    """


#: The command did what was asked.
EXIT_OK = 0
#: A run failed mid-way (partial results kept), or ``compare`` found a deviation.
EXIT_FAILED = 1
#: Bad input or usage: nothing was run.
EXIT_INPUT_ERROR = 2
#: Interrupted by the user (Ctrl-C, SIGINT); any signal N gives ``EXIT_SIGNAL_BASE + N``.
EXIT_INTERRUPTED = 130
#: Stopped by signal N (SIGINT, SIGTERM, SIGHUP): exit status ``128 + N`` (130, 143, 129).
EXIT_SIGNAL_BASE = 128
