"""Signals that stop a run: SIGINT, SIGTERM and SIGHUP, all handled like Ctrl-C.

``timeout``, CI cancellation and ``docker stop`` send SIGTERM; closing a terminal sends SIGHUP.
Inside :func:`handling_signals` each of them raises :class:`Interrupted` in the main thread
(a :class:`KeyboardInterrupt` carrying the signal number), so that the run stops at once,
keeps what it computed and writes its summary; the command exits with ``128 + signal``
(130, 143, 129).

Some libraries swallow the exception (casadi turns one raised inside a solver callback into a
failed solve; pythonfmu turns one inside ``doStep`` into an FMU error): the
:class:`SignalGuard` remembers every signal, and the master checks it after each step.
While results are written (:meth:`SignalGuard.deferred`) signals are only recorded, so that
a second Ctrl-C cannot cut a file in half; a third one during that time exits at once.

:func:`alarm` bounds a block of Python code in wall-clock time with ``SIGALRM`` (the
controller step of ``--step-timeout``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator
from types import FrameType

__all__ = ["HANDLED", "Interrupted", "SignalGuard", "StepTimeout", "alarm", "current",
           "handling_signals", "signal_name"]

#: Signals handled like Ctrl-C.
HANDLED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def signal_name(signum: int) -> str:
    """``"SIGTERM"`` for 15 (the number itself when unknown)."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return str(signum)


class Interrupted(KeyboardInterrupt):
    """A run stopped by a signal; :attr:`exit_code` is ``128 + signum``."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signal_name(signum))
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        """The exit status a shell expects after this signal."""
        return 128 + self.signum


class StepTimeout(Exception):
    """Raised by :func:`alarm` in the main thread when the time limit passes."""


class SignalGuard:
    """Records SIGINT/SIGTERM/SIGHUP and raises :class:`Interrupted` (see the module doc).

    Two modes: *raising* (the default: the handler raises :class:`Interrupted` where the
    main thread is) and *deferred* (inside :meth:`deferred`: the signal is only recorded,
    and a third one exits the process at once). :meth:`raising` re-enables raising inside a
    deferred block (the master's step loop).

    Attributes
    ----------
    signum : int or None
        The first signal received, ``None`` while none was.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self._defer = 0
        self._deferred_count = 0

    def handler(self, signum: int, frame: FrameType | None) -> None:
        """The signal handler installed by :func:`handling_signals`."""
        if self.signum is None:
            self.signum = signum
        if self._defer:
            self._deferred_count += 1
            if self._deferred_count >= 3:  # asked three times: leave now
                os._exit(128 + signum)
            return
        raise Interrupted(signum)

    def check(self) -> None:
        """Raise :class:`Interrupted` if a signal arrived (and was swallowed by a library).

        Does nothing inside a :meth:`deferred` block.
        """
        if self.signum is not None and not self._defer:
            raise Interrupted(self.signum)

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Within the block signals are recorded, not raised (files being written)."""
        self._defer += 1
        try:
            yield
        finally:
            self._defer -= 1

    @contextlib.contextmanager
    def raising(self) -> Iterator[None]:
        """Within the block signals raise, even inside :meth:`deferred`; a signal recorded
        before the block raises on entry."""
        saved, self._defer = self._defer, 0
        try:
            self.check()
            yield
        finally:
            self._defer = saved


_CURRENT: list[SignalGuard] = []


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def current() -> SignalGuard | None:
    """The guard of the innermost active :func:`handling_signals` block, if any; always
    ``None`` outside the main thread.

    Signals are delivered to the main thread only, and a guard's counters belong to the code
    that runs there: another thread (a run on a multi-threaded Dask worker, a campaign
    started from a thread) never sees nor changes the main thread's guard.
    """
    return _CURRENT[-1] if _CURRENT and _main_thread() else None


@contextlib.contextmanager
def handling_signals() -> Iterator[SignalGuard | None]:
    """Install the handlers for the block (main thread only; elsewhere yields ``None``).

    Nested use reuses the outer guard. A signal whose disposition is ``SIG_IGN`` (a
    process started with ``nohup``, or a worker told to ignore Ctrl-C) stays ignored.
    """
    if not _main_thread():
        yield None
        return
    if _CURRENT:
        yield _CURRENT[-1]
        return
    guard = SignalGuard()
    previous = {}
    for sig in HANDLED:
        if signal.getsignal(sig) is not signal.SIG_IGN:
            previous[sig] = signal.signal(sig, guard.handler)
    _CURRENT.append(guard)
    try:
        yield guard
    finally:
        _CURRENT.pop()
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def alarm(seconds: float | None) -> Iterator[list[bool]]:
    """Raise :class:`StepTimeout` in the block after ``seconds`` of wall time.

    Yields a list that holds ``True`` once the limit has passed (the exception may have
    been swallowed by a library). Without a limit, or outside the main thread, nothing is
    armed (the caller may still compare the elapsed time).
    """
    fired: list[bool] = []
    if not seconds or threading.current_thread() is not threading.main_thread():
        yield fired
        return

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        fired.append(True)
        raise StepTimeout(f"exceeded {seconds:g} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield fired
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
