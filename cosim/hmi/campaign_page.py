"""A campaign's page: its runs with their KPIs, each linked to its own page.

The list is read from the campaign's folder (``runs/<run>-<variant>/summary.json``, as
:mod:`cosim.campaign.store` writes them), so it shows a campaign going on (``cosim campaign
--hmi``: read again every :data:`REFRESH_MS`) as well as a finished one (``cosim view
CAMPAIGN_DIR``). ``/run?name=<run>-<variant>`` is that run's page
(:func:`cosim.hmi.replay.load`, with its time slider).
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cosim.hmi.actions import User
from cosim.hmi.page import RunPage
from cosim.hmi.panels import fmt

__all__ = ["REFRESH_MS", "is_campaign_folder", "pages", "run_table"]

#: How often a campaign going on is read again [ms].
REFRESH_MS = 2000


def is_campaign_folder(path: Path) -> bool:
    """Whether ``path`` holds a campaign (its ``campaign.json``)."""
    return (path / "campaign.json").is_file()


class RunTable:
    """The runs on disk, each summary read once (a run's summary is written when it ends)."""

    def __init__(self, folder: Path) -> None:
        self.runs = folder / "runs"
        self.seen: dict[str, dict[str, Any]] = {}

    def read(self) -> list[dict[str, Any]]:
        """One entry per finished run: its name, status, reason and KPIs."""
        if self.runs.is_dir():
            for path in sorted(self.runs.glob("*/summary.json")):
                name = path.parent.name
                if name in self.seen:
                    continue
                try:
                    doc = json.loads(path.read_text(encoding="utf-8"))
                except (OSError, ValueError):
                    continue   # being written: read next time
                self.seen[name] = _entry(name, doc)
        return [self.seen[k] for k in sorted(self.seen)]


def _entry(name: str, doc: dict[str, Any]) -> dict[str, Any]:
    kpis = doc.get("kpis") or {}
    iae = kpis.get("iae") or {}
    violations = sum(int((v or {}).get("count", 0)) for v in
                     (kpis.get("violations") or {}).values())
    return {"name": name, "status": str(doc.get("status", "")),
            "reason": str(doc.get("reason") or ""), "violations": violations,
            "iae": {str(k): float(v) if v is not None else math.nan for k, v in iae.items()}}


def run_table(entries: list[dict[str, Any]]) -> str:
    """The runs as an HTML table, each name a link to its page."""
    outputs = sorted({o for e in entries for o in e["iae"]})
    head = "".join(f"<th>IAE {html.escape(o)}</th>" for o in outputs)
    rows = []
    for e in entries:
        name = html.escape(e["name"])
        cells = "".join(f"<td>{fmt(e['iae'].get(o, math.nan))}</td>" for o in outputs)
        style = "" if e["status"] in ("ok", "degraded") else ' style="color:#d62728"'
        rows.append(f'<tr class="hmi-run" data-run="{name}"><td><a href="/run?name={name}">'
                    f"{name}</a></td><td{style}>{html.escape(e['status'])}</td>"
                    f"<td>{e['violations']}</td>{cells}"
                    f"<td>{html.escape(e['reason'][:120])}</td></tr>")
    return (f'<table class="hmi-runs" style="border-collapse:collapse" cellpadding=4>'
            f"<tr><th>run</th><th>status</th><th>violations</th>{head}<th>reason</th></tr>"
            f"{''.join(rows)}</table>")


def pages(folder: Path, live: bool = False) -> dict[str, Callable[[Any, User | None, bytes],
                                                                  None]]:
    """The campaign's list (``/``) and its runs' pages (``/run``) for
    :class:`cosim.hmi.server.PageServer`."""
    table = RunTable(folder)

    def listing(doc: Any, _user: User | None, _secret: bytes) -> None:
        from bokeh.models import Div

        div = Div(text="", sizing_mode="stretch_width", css_classes=["hmi-campaign"])

        def refresh() -> None:
            entries = table.read()
            state = "going on" if live else "finished"
            div.text = (f"<h2>campaign {html.escape(folder.name)} ({state}): "
                        f"{len(entries)} runs on disk</h2>{run_table(entries)}")

        refresh()
        doc.add_root(div)
        doc.title = f"cosim · campaign {folder.name}"
        if live:
            doc.add_periodic_callback(refresh, REFRESH_MS)

    def one_run(doc: Any, user: User | None, _secret: bytes) -> None:
        from bokeh.models import Div

        from cosim.core.errors import CosimError
        from cosim.hmi import replay

        args = doc.session_context.request.arguments if doc.session_context else {}
        name = (args.get("name") or [b""])[0]
        name = name.decode() if isinstance(name, bytes) else str(name)
        known = {p.name for p in table.runs.iterdir()} if table.runs.is_dir() else set()
        try:
            if name not in known:   # only a folder of runs/, never a path
                raise CosimError(f"no run {name!r} in {table.runs}")
            RunPage(doc, replay.load(table.runs / name), user, live=False)
        except CosimError as exc:
            doc.add_root(Div(text=f'<p class="hmi-error">{html.escape(str(exc))}</p>'))

    return {"/": listing, "/run": one_run}
