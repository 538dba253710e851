"""What the run's page costs the run: the step time of a run with ``--hmi`` and the page open
in a browser, against the same run without, in the same process.

The paper's scenario (1,600 steps of the robust MPC, four-tank FMU in process, nothing
written to disk) is run ``--repeats`` times each way, alternately; with the page, a headless
Chromium (Debian's ``chromium``, driven by Playwright) has it open for the whole run, so that
the server pushes every update (:data:`cosim.hmi.page.PERIOD_MS`) and the feed reads the
controller's plan after each step. The step time is the loop's time (first step to last) per
step. Prints the median of each and their ratio (goal: ≤ 1.05); without a browser the page
is served with nobody looking, and it says so.

On a machine with two cores the browser draws the page on one of them: the ratio then holds
what the browser takes from the run too (a page read on another computer does not).

Usage: ``python benchmarks/bench_hmi.py [--repeats R] [--scenario CSV]``
"""

from __future__ import annotations

import argparse
import contextlib
import shutil
import statistics
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cosim  # noqa: E402
from cosim.hmi.serving import HmiOptions  # noqa: E402
from cosim.live.process import free_port  # noqa: E402


@contextlib.contextmanager
def viewer(url_box: list[str]) -> Iterator[threading.Event | None]:
    """A headless Chromium that opens the page once its address is in ``url_box`` and keeps
    it open until the event is set; ``None`` without a browser."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        chromium = None
    if chromium is None:
        yield None
        return
    done, opened = threading.Event(), threading.Event()

    def view() -> None:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True,
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


def one_run(scenario: Path, page: bool) -> float:
    """Seconds per step of one run, with the page (and a browser on it) or without: the wall
    time from the end of its first step to the end of its last, over the steps between (the
    first step waits until the browser shows the page)."""
    url: list[str] = []
    marks: list[float] = []

    def notice(text: str) -> None:
        if text.startswith("the run's page: "):
            url.append(text.rsplit(" ", 1)[1])

    with viewer(url) if page else contextlib.nullcontext(None) as opened:
        def step(k: int) -> None:
            if k == 1 and opened is not None:
                opened.wait(120)
            marks.append(time.perf_counter())

        hmi = HmiOptions("127.0.0.1", free_port()) if page else None
        out = cosim.run(scenario, figure=False, hmi=hmi, on_notice=notice, on_step=step)
    assert out.status == "ok", out.reason
    return (marks[-1] - marks[0]) / (len(marks) - 1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenario", default=str(ROOT / "scenarios" / "paper_steps.csv"))
    args = parser.parse_args(argv)
    scenario = Path(args.scenario)
    one_run(scenario, False)   # warm up: the kernel compiled and loaded, the FMU built
    with viewer([]) as probe:
        has_browser = probe is not None
    base, page = [], []
    for _ in range(args.repeats):
        base.append(one_run(scenario, False))
        page.append(one_run(scenario, True))
    b, p = statistics.median(base), statistics.median(page)
    who = "the page open in headless Chromium" if has_browser else \
        "the page served, no browser (none installed)"
    print(f"{scenario.name}, {args.repeats} runs each way, alternately; {who}")
    print(f"step without the page  {b * 1e3:8.3f} ms  (runs: "
          f"{', '.join(f'{x * 1e3:.3f}' for x in base)})")
    print(f"step with the page     {p * 1e3:8.3f} ms  (runs: "
          f"{', '.join(f'{x * 1e3:.3f}' for x in page)})")
    print(f"ratio {p / b:.3f} (goal <= 1.05)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
