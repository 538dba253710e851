"""What the run's page costs the run: the step time of a run with ``--hmi`` and the page open
in a browser, against the same run without, in the same process.

The paper's scenario (1,600 steps of the robust MPC, four-tank FMU in process, nothing
written to disk) is run ``--repeats`` times each way, alternately: without the page; with it
served and nobody looking (the run's own share: the feed in its loop, the server idle);
with it open in a headless Chromium (Debian's ``chromium``, driven by Playwright) for the
whole run, so that the server pushes every update (:data:`cosim.hmi.page.PERIOD_MS`). The
browser runs twice: niced (``nice -n 19``: meant to draw only on what the run leaves; on
loaded cores it does not quite) and beside the run at the same priority (on a machine of two
cores it then takes one of them). Neither separates the server's pushes (a thread of the
run's process) from the browser's drawing; a third way does, as on the operator's own
computer: the run (with its server's threads) held to core 0, the browser (and Playwright's
driver) to core 1, against the run without the page held to core 0 alike. The step time is
the wall time from the end of the first step (which waits until the browser shows the page)
to the end of the last, per step. Prints the median of each way and its ratio to the run
without the page (goal: ≤ 1.05), then the CPU time per step of the run's other threads (its
server's, with the browser driver's thread left out: :func:`server_cpu`), the page's cost
measured directly where the wall clock of a shared machine scatters.

Usage: ``python benchmarks/bench_hmi.py [--repeats R] [--scenario CSV]``
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cosim  # noqa: E402
from cosim.hmi.serving import HmiOptions  # noqa: E402
from cosim.live.process import free_port  # noqa: E402

#: the run held to core 0 without the page, and with it open in a browser held to core 1
PINNED_BASE, PINNED = "without the page, run on core 0", "page open, browser on core 1"


@contextlib.contextmanager
def viewer(url_box: list[str], nice: int = 0,
           core: int | None = None) -> Iterator[threading.Event | None]:
    """A headless Chromium that opens the page once its address is in ``url_box`` and keeps
    it open until the event is set (``nice``: its processes' niceness; ``core``: the one CPU
    it and Playwright's driver run on); ``None`` without a browser."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        chromium = None
    if chromium is None:
        yield None
        return
    done, opened = threading.Event(), threading.Event()

    folder = tempfile.mkdtemp()
    launcher = Path(folder) / "chromium"
    launcher.write_text(f'#!/bin/sh\nexec nice -n {nice} "{chromium}" "$@"\n')
    launcher.chmod(0o755)

    def view() -> None:
        opened.tid = threading.get_native_id()   # type: ignore[attr-defined]
        if core is not None:   # this thread, and what it starts, on that core alone
            os.sched_setaffinity(0, {core})
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(launcher), headless=True,
                                         args=["--no-sandbox", "--disable-dev-shm-usage"])
            page = browser.new_page(viewport={"width": 1280, "height": 1400})
            while not url_box and not done.is_set():
                time.sleep(0.01)
            if url_box:
                page.goto(url_box[0])
                page.wait_for_selector(".hmi-value", timeout=120_000)
                opened.set()
                done.wait()
            browser.close()

    thread = threading.Thread(target=view, daemon=True)
    thread.start()
    try:
        yield opened
    finally:
        done.set()
        thread.join(60)
        shutil.rmtree(folder, ignore_errors=True)


def one_run(scenario: Path, page: bool, browse: bool = True, nice: int = 0,
            pin: bool = False) -> tuple[float, float]:
    """Seconds per step of one run, with the page (and a browser on it) or without: the wall
    time from the end of its first step to the end of its last, over the steps between (the
    first step waits until the browser shows the page), and the CPU seconds per step of the
    run's other threads (:func:`server_cpu`). ``pin``: the run on core 0, the browser on
    core 1."""
    url: list[str] = []
    marks: list[float] = []
    others: list[float] = []   # the CPU seconds of the run's other threads: its server's

    def notice(text: str) -> None:
        if text.startswith("the run's page: "):
            url.append(text.rsplit(" ", 1)[1])

    every = os.sched_getaffinity(0)
    with viewer(url, nice, 1 if pin else None) if page and browse else \
            contextlib.nullcontext(None) as opened:
        def step(k: int) -> None:
            if k == 1 and opened is not None:
                opened.wait(120)
            marks.append(time.perf_counter())
            if k == 1:
                others.append(server_cpu(opened))

        hmi = HmiOptions("127.0.0.1", free_port()) if page else None
        if pin:   # the run's thread, and the server threads it starts, on core 0
            os.sched_setaffinity(0, {0})
        try:
            out = cosim.run(scenario, figure=False, hmi=hmi, on_notice=notice, on_step=step)
        finally:
            os.sched_setaffinity(0, every)
        others.append(server_cpu(opened))
    assert out.status == "ok", out.reason
    steps = len(marks) - 1
    return (marks[-1] - marks[0]) / steps, (others[-1] - others[0]) / steps


def server_cpu(viewer_event: Any) -> float:
    """CPU seconds of this process's threads but the run's (this one) and the browser's
    driver thread (``viewer_event.tid``): the page's server, from the first step on to the
    run's end (its last pushes included)."""
    cpu = time.process_time() - time.thread_time()
    tid = getattr(viewer_event, "tid", None)
    if tid is not None:
        with contextlib.suppress(OSError), open(f"/proc/self/task/{tid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
            cpu -= (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return cpu


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenario", default=str(ROOT / "scenarios" / "paper_steps.csv"))
    parser.add_argument("--no-browser", action="store_true",
                        help="serve the page with nobody looking (the run's own share only)")
    args = parser.parse_args(argv)
    scenario = Path(args.scenario)
    one_run(scenario, False)   # warm up: the kernel compiled and loaded, the FMU built
    has_browser = False
    if not args.no_browser:
        with viewer([]) as probe:
            has_browser = probe is not None
    # (label, page served, browser, its niceness, pinned)
    ways = [("without the page", False, False, 0, False),
            ("page, nobody looking", True, False, 0, False)]
    if has_browser:
        ways += [("page open, browser niced", True, True, 19, False),
                 ("page open, browser beside", True, True, 0, False)]
    pinned = has_browser and len(os.sched_getaffinity(0)) >= 2
    if pinned:
        ways += [(PINNED_BASE, False, False, 0, True), (PINNED, True, True, 0, True)]

    times: dict[str, list[float]] = {w[0]: [] for w in ways}
    server: dict[str, list[float]] = {w[0]: [] for w in ways}
    for _ in range(args.repeats):
        for label, page, browse, nice, pin in ways:
            step, cpu = one_run(scenario, page, browse, nice, pin)
            times[label].append(step)
            server[label].append(cpu)
    base = statistics.median(times[ways[0][0]])
    print(f"{scenario.name}: step time, median of {args.repeats} runs each way, alternately"
          + ("" if has_browser or args.no_browser else " (no browser installed)"))
    for label, *_ in ways:
        m = statistics.median(times[label])
        ref = statistics.median(times[PINNED_BASE]) if label == PINNED else base
        print(f"{label:34s} {m * 1e3:8.3f} ms  ratio {m / ref:5.3f}  (runs: "
              f"{', '.join(f'{x * 1e3:.3f}' for x in times[label])})")
    print("the other threads' CPU per step (the page's server; the browser's driver thread "
          "left out), against the step without the page:")
    for label, *_ in ways:
        c = statistics.median(server[label])
        print(f"  {label:34s} {c * 1e3:8.3f} ms  {100 * c / base:5.1f} %")
    print("goal: ratio <= 1.05 with the page open (the browser on core 1: as on the "
          "operator's own computer, its ratio against the run on core 0 without the page; "
          "niced or beside: on this machine's cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
