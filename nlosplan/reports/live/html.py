"""Small HTML pieces of the live pages: the one escaping helper, tables of whatever rows a file holds, numbers,
durations.

Every text a live page puts into a Bokeh ``Div`` (whose HTML BokehJS renders with ``innerHTML``) that came
from a file, a flag, a store or a peer (run ids, object names, failure reasons, paths, the approval's note
and who answered, a design folder and label, error messages) goes through :func:`esc` first; only the
markup the page itself writes is left as it is. Attribute values are always quoted (``title="..."``,
``data-col="..."``) and escaped with the quotes; no page builds JavaScript from strings.
"""

from __future__ import annotations

import html
import json
import math

__all__ = ["duration", "esc", "fmt", "table"]


def esc(value) -> str:
    """``value`` as text safe inside HTML: ``& < > " '`` escaped (for element text and quoted attributes).

    Parameters
    ----------
    value : object
        Anything; shown as ``str(value)`` (format it first with :func:`fmt` where a number is meant).

    Returns
    -------
    str
        The text with ``&``, ``<``, ``>``, ``"`` and ``'`` as character references, so a run id such as
        ``<img src=x onerror=alert(1)>`` shows as these characters and never becomes an element.
    """
    return html.escape(str(value), quote=True)


def fmt(v) -> str:
    """A value as a table cell shows it: 4 significant digits, lists and dicts as compact JSON."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "—"
        if math.isinf(v):
            return "∞" if v > 0 else "-∞"
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v):
        return f"[{fmt(v[0])}, {fmt(v[1])}]"
    if isinstance(v, (list, tuple, dict)):
        return json.dumps(v, separators=(",", ":"), default=str)
    return str(v)


def duration(seconds) -> str:
    """``42 s``, ``3.5 min``, ``2.1 h`` (``—`` when unknown)."""
    if seconds is None or not math.isfinite(seconds):
        return "—"
    s = float(seconds)
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


def table(rows: list[dict], *, name: str, columns: list[str] | None = None, drop=(), limit: int = 60) -> str:
    """An HTML table of dict rows, with the union of their keys as columns (or ``columns``), in order.

    Cells carry ``data-col`` (the key) so a test or a user can find a value; long cells are cut at
    ``limit`` characters (the whole text in the cell's title).
    """
    if not rows:
        return f'<table class="nl-table" data-name="{esc(name)}"><tr><td>none yet</td></tr></table>'
    if columns is None:
        columns = []
        for r in rows:
            columns += [k for k in r if k not in columns and k not in drop]
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    body = []
    for r in rows:
        cells = []
        for c in columns:
            text = fmt(r.get(c))
            short = text if len(text) <= limit else text[: limit - 1] + "…"
            cells.append(f'<td data-col="{esc(c)}" title="{esc(text)}">{esc(short)}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<table class="nl-table" data-name="{esc(name)}"><thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table>')


STYLE = """<style>
.nl-table {border-collapse: collapse; font: 12px sans-serif; margin: 4px 0 10px 0}
.nl-table th, .nl-table td {border: 1px solid #ccc; padding: 2px 6px; text-align: left; white-space: nowrap}
.nl-table th {background: #f0f0f0}
.nl-status {font: 13px sans-serif; line-height: 1.5}
.nl-status b {font-weight: 600}
.nl-warn {color: #a33}
.nl-ok {color: #275}
</style>"""
