"""Self-contained HTML reports: sections of text, tables of figures and embedded plots.

Plots are matplotlib figures rendered to PNG with the Agg canvas (no display, no
pyplot state, safe in threads) and embedded as base64 ``data:`` URIs, so the report is
one file that opens anywhere, offline. Numbers are shown in tables; NaN prints as
an en dash.

::

    report = HtmlReport("mocapkit demo")
    sec = report.section("Teleoperation", "A simulated suit drives ...")
    sec.table(["figure", "value"], [["ee_rmse_mm", 8.2]])
    sec.figure(fig, "Commanded and achieved end-effector paths")
    path = report.write("out/report.html")
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from mocapkit import __version__

_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { border-bottom: 2px solid #2a5bd7; padding-bottom: .2em; }
h2 { margin-top: 2em; color: #2a5bd7; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: .3em .7em; text-align: right; }
th { background: #f0f3fa; }
td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
.note { font-size: .9em; color: #555; }
"""


def format_value(value: Any) -> str:
    """A table cell: floats to 4 significant digits, NaN/None as an en dash."""
    if value is None:
        return "\u2013"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "\u2013"
        return f"{value:.4g}"
    return str(value)


def figure_png(fig: Figure, dpi: int = 110) -> bytes:
    """Render a matplotlib figure to PNG bytes with the Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


@dataclass
class Section:
    """One ``<h2>`` section: paragraphs, tables and figures in the order added."""

    title: str
    parts: list[str] = field(default_factory=list)

    def text(self, paragraph: str) -> Section:
        self.parts.append(f"<p>{html.escape(paragraph)}</p>")
        return self

    def note(self, paragraph: str) -> Section:
        self.parts.append(f'<p class="note">{html.escape(paragraph)}</p>')
        return self

    def table(
        self, header: Sequence[str], rows: Sequence[Sequence[Any]], caption: str | None = None
    ) -> Section:
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(format_value(v))}</td>" for v in row) + "</tr>"
            for row in rows
        )
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self.parts.append(f"<table>{cap}<tr>{head}</tr>{body}</table>")
        return self

    def figure(self, fig: Figure | bytes, caption: str) -> Section:
        """Embed a matplotlib figure (or PNG bytes) with a caption."""
        png = fig if isinstance(fig, bytes) else figure_png(fig)
        data = base64.b64encode(png).decode("ascii")
        self.parts.append(
            f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
        return self


class HtmlReport:
    """A report being built; :meth:`write` produces the single HTML file."""

    def __init__(self, title: str, intro: str = "") -> None:
        self.title = title
        self.intro = intro
        self.sections: list[Section] = []

    def section(self, title: str, text: str = "") -> Section:
        sec = Section(title)
        if text:
            sec.text(text)
        self.sections.append(sec)
        return sec

    def html(self) -> str:
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        toc = "".join(
            f'<li><a href="#s{i}">{html.escape(s.title)}</a></li>'
            for i, s in enumerate(self.sections)
        )
        body = "".join(
            f'<h2 id="s{i}">{html.escape(s.title)}</h2>' + "".join(s.parts)
            for i, s in enumerate(self.sections)
        )
        intro = f"<p>{html.escape(self.intro)}</p>" if self.intro else ""
        return (
            "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1>{intro}"
            f'<p class="note">mocapkit {__version__}, {stamp}</p><ul>{toc}</ul>{body}'
            "</body></html>\n"
        )

    def write(self, path: str | Path) -> Path:
        """Write the report (parent folders created); returns the path."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(self.html(), encoding="utf-8")
        return p
