"""A real headless Chromium for the page's tests: Debian's ``chromium`` (``make browser``
installs it) driven by Playwright through ``executable_path``; Playwright's own browser
download is never used. Where no browser can be had the tests skip with one line."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[3]
#: The screenshot the docs show (docs/guide/live.md), written when ``COSIM_SCREENSHOT=1``.
DOCS_SCREENSHOT = ROOT / "docs" / "assets" / "hmi_live.png"


def chromium() -> str | None:
    """The browser's executable: ``$COSIM_CHROMIUM``, else ``chromium`` on the path."""
    given = os.environ.get("COSIM_CHROMIUM")
    if given:
        return given if Path(given).exists() else None
    return shutil.which("chromium") or shutil.which("chromium-browser")


@contextlib.contextmanager
def browser() -> Iterator[Any]:
    """A headless Chromium (Playwright's ``Browser``), closed after the block."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("no browser: playwright is not installed (pip install -e '.[dev]')")
    path = chromium()
    if path is None:
        pytest.skip("no browser: Debian's chromium is not installed (make browser)")
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=path, headless=True,
                               args=["--no-sandbox", "--disable-dev-shm-usage"])
        try:
            yield b
        finally:
            b.close()


def env(**extra: str) -> dict[str, str]:
    """The environment of a ``cosim`` subprocess (the repository importable)."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra)


def cosim(*args: str) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", *args]


def start(args: list[str], log: Path, cwd: Path | None = None,
          extra_env: dict[str, str] | None = None) -> subprocess.Popen:
    """A ``cosim`` command in its own process, its standard error in ``log``."""
    with open(log, "w") as fh:   # the child keeps its own copy
        return subprocess.Popen(args, cwd=cwd, env=env(**(extra_env or {})),
                                stdout=subprocess.DEVNULL, stderr=fh)


def wait_for_line(proc: subprocess.Popen, log: Path, start: str, timeout: float) -> str:
    """The first line of ``log`` that starts with ``start`` (the process must not end
    before it comes)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for line in log.read_text().splitlines():
            if line.startswith(start):
                return line
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    raise AssertionError(f"no line {start!r} within {timeout:g} s:\n{log.read_text()}")


def stop(proc: subprocess.Popen, timeout: float = 20.0) -> int:
    """End ``proc`` (SIGINT, then SIGKILL); its exit code."""
    if proc.poll() is None:
        proc.send_signal(2)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout)
    return proc.returncode


def readouts(page: Any) -> dict[str, dict[str, str]]:
    """Every panel's readout: its ``data-*`` attributes, by signal (Playwright's selectors
    reach into Bokeh's shadow roots)."""
    values = page.locator(".hmi-value").evaluate_all("els => els.map(e => ({...e.dataset}))")
    return {v["signal"]: v for v in values}


def badges(page: Any) -> dict[str, str]:
    """The status strip: each badge's value, by key."""
    values = page.locator(".hmi-badge").evaluate_all("els => els.map(e => ({...e.dataset}))")
    return {v["key"]: v["value"] for v in values}


def wait_until(what: Any, timeout: float, step: float = 0.2) -> Any:
    """``what()`` once it is true (an ``AssertionError`` after ``timeout`` seconds)."""
    end = time.monotonic() + timeout
    while True:
        value = what()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout:g} s: {what}")
        time.sleep(step)
