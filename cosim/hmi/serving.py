"""Serving a page: a run's as it goes (:func:`watching`, what ``cosim run --hmi`` and
:func:`cosim.api.run` with ``hmi`` do), a finished run's or a campaign's (:func:`serve_folder`,
``cosim view``), and a campaign's as it goes (:func:`serving_campaign`).

:class:`HmiOptions` is the page's address and users, read from ``--hmi [HOST:]PORT`` and
``--hmi-users FILE``.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.hmi.actions import operator_for
from cosim.hmi.feed import Feed, Layout
from cosim.hmi.page import PERIOD_MS, run_page
from cosim.hmi.server import PageServer, parse_address
from cosim.hmi.users import Users

__all__ = ["HmiOptions", "serve_folder", "serving_campaign", "watching"]


@dataclass(frozen=True)
class HmiOptions:
    """Where a page is served and who may log in.

    Attributes
    ----------
    host, port : str, int
        The address (:func:`cosim.hmi.server.parse_address`).
    users : Users or None
        Who may write (``None``: nobody; viewing only, on the loopback interface).
    flag : str
        The option that named the address (quoted in errors).
    """

    host: str
    port: int
    users: Users | None = None
    flag: str = "--hmi"

    @staticmethod
    def parse(address: str | int, users: str | Path | None = None,
              flag: str = "--hmi") -> HmiOptions:
        """The options of ``--hmi ADDRESS`` and ``--hmi-users FILE``.

        Raises
        ------
        CosimError
            A bad address or users file (one line naming the flag).
        """
        host, port = parse_address(str(address), flag)
        return HmiOptions(host, port, Users.load(users) if users is not None else None, flag)

    def server(self, pages: Mapping[str, Callable[..., None]]) -> PageServer:
        """A server of ``pages`` at this address (not started)."""
        return PageServer(pages, self.host, self.port, self.users, self.flag)


@contextlib.contextmanager
def watching(master: Any, meta: Mapping[str, Any], options: HmiOptions,
             on_notice: Callable[[str], None] | None = None) -> Iterator[Feed]:
    """The page of the run of ``master`` for the ``with`` block: its feed (the run's
    watcher), served at ``options``' address; the requests go through the run's operator
    desk (:func:`cosim.hmi.actions.operator_for`), whose audit is the run's
    ``operator.csv``. Once the block ends (after :meth:`Feed.finish`) the pages get the
    run's end, then the server stops.

    Raises
    ------
    CosimError
        The address cannot be listened on (nothing has run).
    """
    feed = Feed(Layout.of_run(master, meta), master.controller, operator_for(master))
    server = options.server({"/": run_page(feed, live=True)}).start()
    if on_notice is not None:
        on_notice(f"the run's page: {server.url}")
    try:
        yield feed
    finally:
        if feed.status == "running":
            feed.finish("interrupted")
        time.sleep(2 * PERIOD_MS / 1000)   # the pages' last update: the run's end
        server.stop()


def serve_folder(folder: str | Path, options: HmiOptions, duration: float | None = None,
                 on_notice: Callable[[str], None] | None = None) -> None:
    """Serve the page of a finished run's folder, or of a campaign's folder (its runs
    listed with their KPIs, each linked to its page), until a signal or ``duration``
    seconds.

    Raises
    ------
    CosimError
        ``folder`` is neither (one line naming it), or the address cannot be listened on.
    """
    from cosim.hmi import campaign_page, replay

    folder = Path(folder)
    if campaign_page.is_campaign_folder(folder):
        pages = campaign_page.pages(folder)
    else:
        pages = {"/": run_page(replay.load(folder), live=False)}
    with options.server(pages) as server:
        if on_notice is not None:
            on_notice(f"{folder}: {server.url}")
        end = math.inf if duration is None else time.monotonic() + duration
        while time.monotonic() < end:
            time.sleep(min(0.2, max(0.0, end - time.monotonic())))


@contextlib.contextmanager
def serving_campaign(out: Path, options: HmiOptions,
                     on_notice: Callable[[str], None] | None = None) -> Iterator[None]:
    """A campaign's page (its runs as they finish) for the ``with`` block.

    Raises
    ------
    CosimError
        The address cannot be listened on (nothing has run).
    """
    from cosim.hmi import campaign_page

    with options.server(campaign_page.pages(out, live=True)) as server:
        if on_notice is not None:
            on_notice(f"the campaign's page: {server.url}")
        yield

