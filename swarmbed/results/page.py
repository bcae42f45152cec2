"""One HTML page of figures and tables, as the run, sweep and soak reports write it: plotly's
script goes in once, with the first figure; every figure and table says which file it came from."""

from __future__ import annotations

import html
from typing import Any

import numpy as np
import plotly.graph_objects as go
import plotly.io as pio


class Page:
    """Sections of figures and tables; plotly's script goes in once, with the first figure."""

    def __init__(self, title: str) -> None:
        self.title = title
        self.parts: list[str] = []
        self.figures = 0

    def heading(self, text: str, note: str = "") -> None:
        self.parts.append(f"<h2>{html.escape(text)}</h2>")
        if note:
            self.parts.append(f"<p class='note'>{html.escape(note)}</p>")

    def table(
        self, rows: list[tuple[str, Any, str]], header: tuple[str, str, str] = ("figure", "value", "from")
    ) -> None:
        cells = "".join(
            f"<tr><td>{html.escape(str(a))}</td><td class='num'>{html.escape(_fmt(b))}</td>"
            f"<td class='src'>{html.escape(c)}</td></tr>"
            for a, b, c in rows
        )
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        self.parts.append(f"<table><tr>{head}</tr>{cells}</table>")

    def figure(self, fig: go.Figure, source: str) -> None:
        fig.update_layout(template="plotly_white", height=420, margin={"l": 60, "r": 20, "t": 50, "b": 50})
        self.parts.append(
            pio.to_html(
                fig,
                full_html=False,
                include_plotlyjs=self.figures == 0,
                div_id=f"fig{self.figures}",
                config={"displaylogo": False},
            )
        )
        self.parts.append(f"<p class='src'>from {html.escape(source)}</p>")
        self.figures += 1

    def render(self, subtitle: str) -> str:
        return (
            f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(self.title)}</title>"
            f"<style>{CSS}</style></head><body><h1>{html.escape(self.title)}</h1>"
            f"<p class='note'>{html.escape(subtitle)}</p>{''.join(self.parts)}</body></html>"
        )


CSS = (
    "body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse;margin:1em 0}td,th{border-bottom:1px solid #ddd;padding:4px 10px;"
    "text-align:left}.num{text-align:right;font-variant-numeric:tabular-nums}.src,.note{color:#777;"
    "font-size:0.85em}h2{margin-top:2em;border-bottom:2px solid #eee}"
)


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return "-" if v is None else ("yes" if v else "NO")
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):,.3g}" if abs(float(v)) < 1000 else f"{float(v):,.0f}"
    return str(v)
