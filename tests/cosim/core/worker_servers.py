"""Servers for :mod:`cosim.core.worker`'s tests, built in the worker process by name
(``tests.cosim.core.worker_servers:Echo``)."""

from __future__ import annotations

import os
import sys
import time

from cosim.core.errors import CosimError


class Echo:
    """Answers, sleeps, prints, dies or refuses on request."""

    def __init__(self, greeting: str = "hello", refuse: bool = False) -> None:
        if refuse:
            raise CosimError("echo: refused to start (bad input)")
        self.greeting = greeting

    def echo(self, value: object) -> tuple:
        return (self.greeting, value)

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)

    def flood(self, megabytes: int) -> int:
        line = "x" * 1023 + "\n"
        for _ in range(megabytes * 1024):
            sys.stdout.write(line)
        sys.stdout.flush()
        return os.getpid()

    def last_words(self, text: str) -> None:
        print(text, file=sys.stderr, flush=True)
        os.abort()

    def exit(self, code: int) -> None:
        os._exit(code)

    def refuse(self) -> None:
        raise CosimError("echo: that value is bad input")

    def fail(self) -> None:
        raise ValueError("an internal error")
