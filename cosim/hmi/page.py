"""A run's page: its panels (:mod:`cosim.hmi.panels`), the status strip, the operator's
switches, and either the run going on (pushed every :data:`PERIOD_MS`) or a finished run
with a time slider.

Each browser session gets its own Bokeh document (:class:`RunPage`), filled from the run's
:class:`~cosim.hmi.feed.Feed` by a callback on the server's thread. A run going faster than
the page follows (a co-simulation at thousands of samples a second) is thinned: each push
carries the samples that arrived since the last one, at most :data:`MAX_POINTS` of them
(every k-th, the last always), and the trend keeps the last :data:`~cosim.hmi.panels.WINDOW`
samples. The readouts, the plan and the status always show the last sample itself.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable, Sequence
from typing import Any

from cosim.hmi.actions import Action, User
from cosim.hmi.feed import Feed
from cosim.hmi.panels import (
    COLORS,
    WINDOW,
    ErrorPanel,
    InputPanel,
    OutputPanel,
    fmt,
    set_text,
)

__all__ = ["MAX_POINTS", "PERIOD_MS", "RunPage", "Tally", "run_page", "status_items"]

#: How often a session is brought up to date [ms].
PERIOD_MS = 500
#: Most samples of a trend one push carries.
MAX_POINTS = 120
#: The robust MPC's step status (its ``status`` diagnostic, :func:`controllers.ocp.
#: solve_status.status_code`) in words.
STATUS_TEXT = {0: "optimal", 1: "infeasible at x̂", 2: "infeasible", 3: "iteration limit",
               4: "answer check failed", 5: "failed"}


def thin(rows: Sequence[Any], most: int) -> list[Any]:
    """Every k-th of ``rows`` so that at most ``most`` remain, the last always kept."""
    n = len(rows)
    if n <= most:
        return list(rows)
    k = math.ceil(n / most)
    return list(rows[(n - 1) % k::k])


class Tally:
    """The counts of the status strip over a run's rows, each row counted once: steps that
    fell back, that were softened, deadline misses and safe writes (a live run's)."""

    def __init__(self, feed: Feed) -> None:
        self.feed = feed
        self.n = 0
        self.counts = {"fallbacks": 0, "softened": 0, "misses": 0, "alarms": 0}

    def update(self, rows: Sequence[Sequence[float]], upto: int) -> Tally:
        """Count rows ``n … upto − 1``; a tally past ``upto`` (a slider moved back) starts
        over."""
        if upto < self.n:
            self.n, self.counts = 0, dict.fromkeys(self.counts, 0)
        col, c = self.feed.column, self.counts
        jb, js, jf, jo, jw, ja = (col(n) for n in (
            "ctrl.fallback", "ctrl.softened", "live.fresh", "live.on_time", "ctrl.status",
            "live.safe"))
        for r in rows[self.n:upto]:
            width = len(r)
            if jb is not None and jb < width and r[jb] == 1.0:
                c["fallbacks"] += 1
            if js is not None and js < width and r[js] > 0:
                c["softened"] += 1
            if None not in (jf, jo, jw) and max(jf, jo, jw) < width and r[jf] == 1.0 \
                    and r[jo] == 0.0 and math.isfinite(r[jw]):   # type: ignore[index]
                c["misses"] += 1
            if ja is not None and ja < width and r[ja] == 1.0:
                c["alarms"] += 1
        self.n = max(self.n, upto)
        return self


def status_items(feed: Feed, last: Sequence[float] | None,
                 tally: Tally) -> list[tuple[str, str, str]]:
    """The status strip of the run at its row ``last`` (``None``: before the first), the
    counts up to it in ``tally``: ``(key, text, level)``."""
    lay, counts = feed.layout, tally.counts
    t = last[0] if last is not None else lay.start_time
    state = "running" if feed.status == "running" else f"ended {feed.status}"
    items = [("run", f"{state} · t = {fmt(t)} of {fmt(lay.stop_time)} s",
              "normal" if feed.status in ("running", "ok") else "past")]
    mode = "manual" if _switch(feed, "op.mode") == 0.0 else "auto"
    items.append(("mode", mode, "normal" if mode == "auto" else "near"))
    if lay.certificate:
        certified = lay.certificate == "certified"
        items.append(("certificate", "certified" if certified else "uncertified",
                      "normal" if certified else "near"))
    if last is not None and feed.column("ctrl.status") is not None:
        code = feed.value(last, "ctrl.status")
        text = STATUS_TEXT.get(int(code), "failed") if math.isfinite(code) else "–"
        its = feed.value(last, "ctrl.iterations")
        items.append(("solver", f"{text}, {fmt(its)} iterations",
                      "normal" if code == 0 else "near"))
    items.append(("step", _step_text(feed), "normal"))
    for key, column, word in (("fallbacks", "ctrl.fallback", "fallbacks"),
                              ("softened", "ctrl.softened", "softened steps")):
        if feed.column(column) is not None:
            n = counts[key]
            items.append((key, f"{n} {word}", "normal" if n == 0 else "near"))
    if lay.live and last is not None:
        fresh = feed.value(last, "live.fresh") == 1.0
        misses, alarms = counts["misses"], counts["alarms"]
        watchdog = "ALARM" if feed.value(last, "live.safe") == 1.0 else "ok"
        items += [("fresh", "fresh" if fresh else "stale", "normal" if fresh else "past"),
                  ("deadline", f"{misses} deadline misses", "normal" if not misses else "near"),
                  ("watchdog", f"watchdog {watchdog} ({alarms} safe writes)",
                   "normal" if not alarms else "past")]
    return items


def _step_text(feed: Feed) -> str:
    """The controller's last step time and the loop's median step."""
    parts = []
    if "solve_ms" in feed.layout.timing and feed.timing_rows:
        j = 1 + feed.layout.timing.index("solve_ms")
        row = feed.timing_rows[-1]
        parts.append(f"solve {fmt(row[j])} ms" if j < len(row) else "")
    if feed.loop_s:
        loop = sorted(feed.loop_s)[len(feed.loop_s) // 2]
        parts.append(f"loop {fmt(loop * 1e3)} ms")
    return " · ".join(p for p in parts if p) or "–"


def _badges(items: list[tuple[str, str, str]]) -> str:
    return "".join(
        f'<span class="hmi-badge" data-key="{k}" data-value="{html.escape(text)}" '
        f'style="display:inline-block;margin:2px 6px;padding:2px 8px;border-radius:4px;'
        f'border:1px solid {COLORS[lv]};color:{COLORS[lv] if lv != "normal" else "#222"}">'
        f"<b>{k}</b> {html.escape(text)}</span>" for k, text, lv in items)


class Switches:
    """The operator's switches of a session: one field and one button per action, and the
    answer to the last request."""

    def __init__(self, feed: Feed, user: User | None) -> None:
        from bokeh.models import Button, Div, Spinner

        self.feed, self.user = feed, user
        self.fields: dict[str, Any] = {}
        self.shown: dict[str, Any] = {}
        self.pending: dict[int, str] = {}
        widgets: list[Any] = []
        for a in feed.actions:
            slug = a.name.replace(".", "-")
            allowed = user is not None and user.may(a.role)
            field = Spinner(title=f"{a.label} [{a.unit}]" if a.unit else a.label,
                            value=_number(a.value), mode="float", width=170,
                            low=a.low if math.isfinite(a.low) else None,
                            high=a.high if math.isfinite(a.high) else None,
                            step=_step(a), disabled=not allowed,
                            css_classes=["hmi-switch", f"hmi-switch-{slug}"])
            button = Button(label="apply", width=70, disabled=not allowed,
                            css_classes=["hmi-apply", f"hmi-apply-{slug}"])
            button.on_click(lambda _event=None, name=a.name: self.apply(name))
            self.fields[a.name], self.shown[a.name] = field, a.value
            widgets += [field, button]
        self.reply = Div(text="", css_classes=["hmi-reply"], width=260)
        self.widgets = widgets

    def apply(self, name: str) -> None:
        """Send the field's value as a request (answered at the next sample)."""
        if self.user is None:
            return
        value = self.fields[name].value
        ticket = self.feed.request(name, value, self.user)
        self.pending[ticket] = name
        self.reply.text = f'<span data-state="sent">{html.escape(name)} = {value}: sent</span>'

    def tick(self) -> None:
        """Show the answers that came and the values now."""
        replies = self.feed.replies
        for ticket in [t for t in self.pending if t in replies]:
            name, reply = self.pending.pop(ticket), replies[ticket]
            state = "accepted" if reply.accepted else "refused"
            set_text(self.reply, (
                f'<span data-state="{state}" style="color:'
                f'{COLORS["normal"] if reply.accepted else COLORS["past"]}">'
                f"{html.escape(name)}: {state}"
                f"{': ' + html.escape(reply.text) if reply.text else ''}</span>"))
        for a in self.feed.actions:
            if a.name in self.fields and a.value != self.shown[a.name]:
                self.fields[a.name].value = _number(a.value)
                self.shown[a.name] = a.value


def _audit(rows: Sequence[tuple], t: float) -> str:
    """The operator log: the last rows of the audit up to ``t``."""
    shown = [r for r in rows if r[0] <= t][-8:]
    if not shown:
        return ""
    lines = (html.escape(f"t={r[0]:g} s {r[1]}: {r[2]} {r[3]} → {r[4]}, {r[5]}") for r in shown)
    return "<b>operator log</b><br>" + "<br>".join(
        f'<span class="hmi-audit-row">{line}</span>' for line in lines)


def _number(value: float | str) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _switch(feed: Feed, name: str) -> float | None:
    """The value now of the operator's setting ``name`` (``None``: the run has none)."""
    return next((_number(a.value) for a in feed.actions if a.name == name), None)


def _step(a: Action) -> float:
    if a.choices:   # a switch: 1 or 0
        return 1.0
    v = _number(a.value) or (a.high - a.low if math.isfinite(a.high - a.low) else 1.0)
    return 10.0 ** (math.floor(math.log10(abs(v))) - 1) if v else 0.01


class RunPage:
    """One session's page of a run (module docstring)."""

    def __init__(self, doc: Any, feed: Feed, user: User | None, live: bool) -> None:
        from bokeh.layouts import column, row
        from bokeh.models import DataRange1d, Div, Slider

        self.doc, self.feed, self.user, self.live = doc, feed, user, live
        x_range = DataRange1d(range_padding=0.02)
        lay = feed.layout
        self.outputs = [OutputPanel(o, x_range) for o in lay.outputs]
        self.inputs = [InputPanel(u, x_range) for u in lay.inputs]
        self.error = ErrorPanel(lay.outputs, x_range)
        self.header = Div(text=_header(lay.title, user, live), sizing_mode="stretch_width")
        self.status = Div(text="", css_classes=["hmi-status"], sizing_mode="stretch_width",
                          height=64)
        self.audit = Div(text="", css_classes=["hmi-audit"], width=280)
        self.switches = Switches(feed, user) if live and feed.actions else None
        self.sent, self.errors_sent, self.plan_shown = 0, 0, None
        self.tally = Tally(feed)
        self.slider = None
        panels: list[Any] = []
        for p in (*self.outputs, *self.inputs):
            panels += [p.readout, p.fig]
        if live:
            panels += [self.error.fig]
        sw = self.switches
        side = [column(self.audit, width=280)] if sw is None else [column(
            Div(text="<b>operator</b>"), *[row(*sw.widgets[i:i + 2])
                                          for i in range(0, len(sw.widgets), 2)],
            sw.reply, self.audit, width=280)]
        top = [self.header, self.status]
        if not live and feed.rows:
            self.slider = Slider(start=0, end=max(len(feed.rows) - 1, 1), step=1,
                                 value=len(feed.rows) - 1, title="sample",
                                 sizing_mode="stretch_width", css_classes=["hmi-slider"])
            self.slider.on_change("value", lambda _a, _o, new: self.show(int(new)))
            top.append(self.slider)
        doc.add_root(column(*top, row(column(*panels, sizing_mode="stretch_width"), *side,
                                      sizing_mode="stretch_width"),
                            sizing_mode="stretch_width"))
        doc.title = f"cosim · {lay.title}"
        if live:
            self.tick()
            doc.add_periodic_callback(self.tick, PERIOD_MS)
        else:
            self.show(len(feed.rows) - 1)

    def tick(self) -> None:
        """Bring the session up to date with the run (live), every change in one message."""
        self.doc.hold("combine")
        try:
            self._tick()
        finally:
            self.doc.unhold()

    def _tick(self) -> None:
        feed, n = self.feed, len(self.feed.rows)
        if n > self.sent:
            new = thin(feed.rows[max(self.sent, n - WINDOW):n], MAX_POINTS)
            for p in (*self.outputs, *self.inputs):
                p.hist.stream(p.columns(feed, new), rollover=WINDOW)
            self.sent = n
        if len(feed.errors) > self.errors_sent:
            new_e = thin(feed.errors[max(self.errors_sent, len(feed.errors) - WINDOW):],
                         MAX_POINTS)
            self.error.source.stream(self.error.columns(new_e), rollover=WINDOW)
            self.errors_sent = len(feed.errors)
        plan = feed.prediction
        if plan is not self.plan_shown:
            for p in (*self.outputs, *self.inputs):
                p.show_plan(plan[0] if plan else 0.0, plan[1] if plan else None)
            self.plan_shown = plan
        self._readouts(feed.rows, n - 1)
        if self.switches is not None:
            self.switches.tick()

    def show(self, present: int) -> None:
        """A finished run as it was at sample ``present`` (the slider)."""
        feed = self.feed
        window = thin(feed.rows[max(0, present - WINDOW + 1):present + 1], 4 * MAX_POINTS)
        for p in (*self.outputs, *self.inputs):
            p.hist.data = p.columns(feed, window)
        self._readouts(feed.rows, present)

    def _readouts(self, rows: list[list[float]], i: int) -> None:
        """The readouts and the status strip at row ``i``."""
        feed = self.feed
        if i < 0:
            set_text(self.status, _badges(status_items(feed, None, self.tally)))
            return
        last, before = rows[i], rows[i - 1] if i > 0 else None
        error = feed.errors[-1][1] if feed.errors and self.live else {}
        limits = {a.name: _number(a.value) for a in feed.actions if a.name.startswith("op.")}
        for p in self.outputs:
            p.show_value(feed, last, error.get(p.info.name, math.nan))
            p.show_limits(*(limits.get(f"op.{s}.{p.info.name}") or math.nan
                            for s in ("min", "max")))
        for q in self.inputs:
            out = _switch(feed, f"op.service.{q.info.name}") == 0.0
            q.show_value(feed, last, before, "out of service" if out else "in service")
        tally = self.tally.update(rows, i + 1)
        set_text(self.status, _badges(status_items(feed, last, tally)))
        set_text(self.audit, _audit(feed.audit, last[0]))


def _header(title: str, user: User | None, live: bool) -> str:
    who = (f'{html.escape(user.name)} ({html.escape(user.role)}) · <a href="/logout">log out</a>'
           if user is not None else '<a href="/login">log in to operate</a>' if live else "")
    what = "live" if live else "replay"
    return (f'<div style="display:flex;justify-content:space-between;align-items:baseline">'
            f'<h2 style="margin:4px 0">{html.escape(title)} <small>({what})</small></h2>'
            f'<span class="hmi-user">{who}</span></div>')


def run_page(feed: Feed, live: bool) -> Callable[[Any, User | None, bytes], None]:
    """The page of ``feed`` for :class:`cosim.hmi.server.PageServer`."""

    def make(doc: Any, user: User | None, _secret: bytes) -> None:
        RunPage(doc, feed, user, live)

    return make
