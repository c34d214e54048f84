"""Shared machinery of the reports (ship report, validation report): one matplotlib style, figures embedded
as base64 PNG in self-contained HTML, tables for HTML and for a PDF page, the jinja2 environment."""

from __future__ import annotations

import base64
import io
import textwrap
from pathlib import Path

HERE = Path(__file__).parent
STYLE = HERE / "iceresist.mplstyle"


def pyplot():
    """matplotlib.pyplot on the Agg backend with the project style."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.style.use(str(STYLE))
    return plt


def png64(fig) -> str:
    """The figure as a base64 PNG (for ``<img src="data:image/png;base64,...">``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def html_table(table, columns: dict, na_rep: str = "NaN") -> str:
    """``columns`` {column: heading} of ``table`` as an HTML table, floats to 4 significant digits."""
    return table[list(columns)].rename(columns=columns).to_html(index=False, float_format=lambda v: f"{v:.4g}",
                                                                 border=0, na_rep=na_rep)


def pdf_table_page(plt, table, columns: dict, title: str, na_rep: str = "nan"):
    """A figure holding ``columns`` of ``table`` as a table (one PDF page); text longer than 40 characters (a
    note) wraps, and its row grows to hold it."""
    cells = [[na_rep if v is None or (isinstance(v, float) and v != v) else f"{v:.4g}" if isinstance(v, float)
              else textwrap.fill(str(v), 40) or str(v) for v in row] for row in table[list(columns)].values]
    heights = [max(c.count("\n") + 1 for c in row) for row in cells]
    fig, ax = plt.subplots(figsize=(11.0, 0.4 * sum(heights) + 1.2))
    ax.axis("off")
    if cells:
        labels = [textwrap.fill(str(h), 12) for h in columns.values()]  # headings wrap instead of overlapping
        t = ax.table(cellText=cells, colLabels=labels, loc="center")
        t.auto_set_font_size(False)
        t.set_fontsize(7)
        t.auto_set_column_width(list(range(len(labels))))
        t.scale(1.0, 1.3)
        lines = [max(h.count("\n") + 1 for h in labels)] + heights
        for (row, _), cell in t.get_celld().items():
            cell.set_height(cell.get_height() * lines[row])
    ax.set_title(title)
    return fig


def template_env():
    """jinja2 environment over ``reports/templates``."""
    import jinja2

    return jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE / "templates")), autoescape=False)
