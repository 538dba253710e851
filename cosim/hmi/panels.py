"""The panels of a run's page, drawn with Bokeh: one per controlled output, one per input,
and the prediction error.

An output's panel: the measured value and its set-point scrolling (the last
:data:`WINDOW` samples), the box (the engineer's limits) and the operator's limits where the
run has them, and from the present sample on the controller's predicted trajectory over
its horizon with the tightened constraint its plan keeps. An input's: its value, its box and
the plan. Values are coloured as operators read them (:func:`level`): normal, near a limit
(within :data:`NEAR` of the box's width), past it. Each panel's readout is a line of text
whose ``data-*`` attributes carry the exact numbers shown (a browser test reads them).
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from typing import Any

from cosim.core.component import Prediction
from cosim.hmi.feed import Feed, SignalInfo

__all__ = ["COLORS", "NEAR", "WINDOW", "ErrorPanel", "InputPanel", "OutputPanel", "level",
           "set_text"]

#: Samples a trend shows (older ones scroll out).
WINDOW = 400
#: Share of a box's width within which a value is near its limit.
NEAR = 0.05
#: The colour of each level (normal, near a limit, past it), as operators read them.
COLORS = {"normal": "#1f77b4", "near": "#e69f00", "past": "#d62728"}
_PALETTE = ("#1f77b4", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf")


def level(value: float, low: float, high: float) -> str:
    """``"past"`` outside ``[low, high]``, ``"near"`` within :data:`NEAR` of the width of
    a limit, else ``"normal"`` (a side that is ``nan`` has no limit)."""
    if not math.isfinite(value):
        return "normal"
    if (math.isfinite(low) and value < low) or (math.isfinite(high) and value > high):
        return "past"
    width = high - low if math.isfinite(high - low) else abs(value) or 1.0
    margin = NEAR * width
    near = ((math.isfinite(low) and value < low + margin)
            or (math.isfinite(high) and value > high - margin))
    return "near" if near else "normal"


def fmt(value: float) -> str:
    """A value as a panel shows it (4 significant digits)."""
    return f"{value:.4g}" if math.isfinite(value) else "–"


def _figure(title: str, unit: str, x_range: Any, box: SignalInfo | None = None) -> Any:
    """A trend; its value axis spans the box (and a margin) where it has one, as operators'
    trends span the engineering range."""
    from bokeh.models import Range1d
    from bokeh.plotting import figure

    extra = {}
    if box is not None and math.isfinite(box.high - box.low) and box.high > box.low:
        pad = 0.08 * (box.high - box.low)
        extra["y_range"] = Range1d(box.low - pad, box.high + pad)
    fig = figure(height=210, sizing_mode="stretch_width", x_range=x_range, **extra,
                 title=f"{title} [{unit}]" if unit else title, tools="xpan,xwheel_zoom,reset",
                 toolbar_location="right", x_axis_label="time [s]")
    fig.title.text_font_size = "12pt"
    return fig


def _box(fig: Any, info: SignalInfo, color: str = "#d62728", dash: str = "dashed") -> list:
    """Horizontal lines at the box's ends (none where it has none)."""
    from bokeh.models import Span

    spans = []
    for value in (info.low, info.high):
        span = Span(location=value if math.isfinite(value) else None, dimension="width",
                    line_color=color, line_dash=dash, line_width=1.5,
                    visible=math.isfinite(value))
        fig.add_layout(span)
        spans.append(span)
    return spans


def _readout(kind: str, name: str) -> Any:
    from bokeh.models import Div

    return Div(text="", css_classes=["hmi-readout", f"hmi-{kind}-{name}"], height=22,
               sizing_mode="stretch_width")


def set_text(div: Any, text: str) -> None:
    """A text shown, sent to the browser only when it changed (each change lays the page
    out again there)."""
    if div.text != text:
        div.text = text


class OutputPanel:
    """A controlled output's panel (module docstring)."""

    def __init__(self, info: SignalInfo, x_range: Any) -> None:
        from bokeh.models import ColumnDataSource, Span

        self.info = info
        self.hist = ColumnDataSource({"t": [], "y": [], "ref": []})
        self.plan = ColumnDataSource({"t": [], "y": [], "lo": [], "hi": [], "color": []})
        fig = self.fig = _figure(info.name, info.unit, x_range, info)
        fig.line("t", "y", source=self.hist, line_width=2, color="#222222", legend_label="measured")
        fig.step("t", "ref", source=self.hist, mode="after", color="#2ca02c", line_width=2,
                 line_dash="dashed", legend_label="set-point")
        fig.line("t", "lo", source=self.plan, color="#7f7f7f", line_dash="dotdash",
                 legend_label="tightened")
        fig.line("t", "hi", source=self.plan, color="#7f7f7f", line_dash="dotdash")
        fig.line("t", "y", source=self.plan, color=COLORS["normal"], line_width=1.5,
                 legend_label="prediction")
        fig.scatter("t", "y", source=self.plan, color="color", size=4)
        self.box = _box(fig, info)
        self.operator = _box(fig, SignalInfo(info.name), COLORS["near"], "dotted")
        self.now = Span(location=None, dimension="height", line_color="#999999")
        fig.add_layout(self.now)
        fig.legend.location = "top_left"
        fig.legend.label_text_font_size = "8pt"
        fig.legend.background_fill_alpha = 0.6
        self.readout = _readout("output", info.name)

    def columns(self, feed: Feed, rows: Sequence[Sequence[float]]) -> dict[str, list]:
        """The trend's columns of ``rows``."""
        o = self.info.name
        return {"t": [r[0] for r in rows], "y": [feed.value(r, f"plant.{o}") for r in rows],
                "ref": [feed.value(r, f"ref.{o}") for r in rows]}

    def show_plan(self, t0: float, plan: Prediction | None) -> None:
        """The plan from ``t0`` on (cleared when ``None``)."""
        name, info = self.info.name, self.info
        ys = list(plan.outputs.get(name, ())) if plan is not None else []
        if not ys:
            self.plan.data = {"t": [], "y": [], "lo": [], "hi": [], "color": []}
            return
        lo = [*plan.low.get(name, ()), math.nan][:len(ys)]   # type: ignore[union-attr]
        hi = [*plan.high.get(name, ()), math.nan][:len(ys)]  # type: ignore[union-attr]
        lo += [math.nan] * (len(ys) - len(lo))
        hi += [math.nan] * (len(ys) - len(hi))
        colors = [COLORS["past"] if level(y, info.low, info.high) == "past" else
                  COLORS["near"] if level(y, info.low, info.high) == "near"
                  or level(y, a, b) != "normal" else COLORS["normal"]
                  for y, a, b in zip(ys, lo, hi, strict=True)]
        step = plan.step  # type: ignore[union-attr]
        self.plan.data = {"t": [t0 + i * step for i in range(len(ys))], "y": ys, "lo": lo,
                          "hi": hi, "color": colors}

    def show_limits(self, low: float, high: float) -> None:
        """The operator's limits (``nan``: none)."""
        for span, value in zip(self.operator, (low, high), strict=True):
            span.location = value if math.isfinite(value) else None
            span.visible = math.isfinite(value)

    def show_value(self, feed: Feed, row: Sequence[float], error: float) -> None:
        """The readout of ``row``."""
        info, o = self.info, self.info.name
        y, ref = feed.value(row, f"plant.{o}"), feed.value(row, f"ref.{o}")
        lv = level(y, info.low, info.high)
        plan = feed.prediction
        horizon = len(plan[1].outputs.get(o, ())) if plan is not None else 0
        unit = html.escape(info.unit)
        set_text(self.readout, (
            f'<span class="hmi-value" data-signal="{html.escape(o)}" data-t="{row[0]!r}" '
            f'data-value="{y!r}" data-setpoint="{ref!r}" data-level="{lv}" '
            f'data-horizon="{horizon}" style="color:{COLORS[lv]}">'
            f"<b>{html.escape(o)} {fmt(y)} {unit}</b></span> · set-point {fmt(ref)} {unit} · "
            f"box [{fmt(info.low)}, {fmt(info.high)}] · prediction error {fmt(error)} {unit}"
            f" · {horizon} predicted samples"))
        self.now.location = row[0]


class InputPanel:
    """An input's panel (module docstring)."""

    def __init__(self, info: SignalInfo, x_range: Any) -> None:
        from bokeh.models import ColumnDataSource

        self.info = info
        self.hist = ColumnDataSource({"t": [], "u": []})
        self.plan = ColumnDataSource({"t": [], "u": []})
        fig = self.fig = _figure(info.name, info.unit, x_range, info)
        fig.height = 170
        fig.step("t", "u", source=self.hist, mode="after", line_width=2, color="#222222",
                 legend_label="applied")
        fig.step("t", "u", source=self.plan, mode="after", color=COLORS["normal"],
                 line_dash="dashed", legend_label="planned")
        self.box = _box(fig, info)
        self.operator = _box(fig, SignalInfo(info.name), COLORS["near"], "dotted")
        fig.legend.location = "top_left"
        fig.legend.label_text_font_size = "8pt"
        fig.legend.background_fill_alpha = 0.6
        self.readout = _readout("input", info.name)

    def columns(self, feed: Feed, rows: Sequence[Sequence[float]]) -> dict[str, list]:
        u = self.info.name
        return {"t": [r[0] for r in rows], "u": [feed.value(r, f"ctrl.{u}") for r in rows]}

    def show_plan(self, t0: float, plan: Prediction | None) -> None:
        us = list(plan.inputs.get(self.info.name, ())) if plan is not None else []
        step = plan.step if plan is not None else 0.0
        self.plan.data = {"t": [t0 + i * step for i in range(len(us))], "u": us}

    def show_limits(self, low: float, high: float) -> None:
        OutputPanel.show_limits(self, low, high)  # type: ignore[arg-type]

    def show_value(self, feed: Feed, row: Sequence[float], before: Sequence[float] | None,
                   service: str) -> None:
        info, u = self.info, self.info.name
        value = feed.value(row, f"ctrl.{u}")
        move = value - feed.value(before, f"ctrl.{u}") if before is not None else math.nan
        lv = level(value, info.low, info.high)
        unit = html.escape(info.unit)
        set_text(self.readout, (
            f'<span class="hmi-value" data-signal="{html.escape(u)}" data-t="{row[0]!r}" '
            f'data-value="{value!r}" data-level="{lv}" data-service="{html.escape(service)}" '
            f'style="color:{COLORS[lv]}"><b>{html.escape(u)} {fmt(value)} {unit}</b></span>'
            f" · rate {fmt(move)} {unit}/sample · {html.escape(service)} · "
            f"box [{fmt(info.low)}, {fmt(info.high)}]"))


class ErrorPanel:
    """The one-step prediction error of every output: measured minus what the plan of the
    step before predicted (what a shadow run measures)."""

    def __init__(self, outputs: Sequence[SignalInfo], x_range: Any) -> None:
        from bokeh.models import ColumnDataSource

        self.names = [o.name for o in outputs]
        self.source = ColumnDataSource({"t": [], **{n: [] for n in self.names}})
        fig = self.fig = _figure("prediction error (measured − predicted one sample ahead)",
                                 "", x_range)
        fig.height = 170
        for i, o in enumerate(outputs):
            label = f"{o.name} [{o.unit}]" if o.unit else o.name
            fig.line("t", o.name, source=self.source, color=_PALETTE[i % len(_PALETTE)],
                     line_width=1.5, legend_label=label)
        fig.legend.location = "top_left"
        fig.legend.label_text_font_size = "8pt"

    def columns(self, errors: Sequence[tuple[float, dict[str, float]]]) -> dict[str, list]:
        return {"t": [t for t, _ in errors],
                **{n: [e.get(n, math.nan) for _, e in errors] for n in self.names}}
