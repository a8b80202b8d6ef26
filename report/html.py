"""Formatting of numbers and the HTML pieces of the report: paragraphs, tables, figures.

Every cell and paragraph is escaped; a value that is missing or not a finite number shows as
"n/a" (a missing *file* shows as a note, :func:`missing`).
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from typing import Any


def finite(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool, None or NaN)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def fmt(value: Any, spec: str = ".3g", suffix: str = "") -> str:
    """``value`` formatted, or "n/a" when it is missing or not a finite number."""
    return f"{value:{spec}}{suffix}" if finite(value) else "n/a"


def pm(mean: Any, sd: Any, spec: str = ".3g") -> str:
    """``mean ± sd``, the mean alone without an SD, or n/a."""
    if not finite(mean):
        return "n/a"
    return f"{mean:{spec}} ± {sd:{spec}}" if finite(sd) else f"{mean:{spec}}"


def seconds(value: Any) -> str:
    """A duration with a unit that keeps it readable (µs to h)."""
    if not finite(value):
        return "n/a"
    if value < 1e-3:
        return f"{1e6 * value:.3g} µs"
    if value < 1.0:
        return f"{1e3 * value:.3g} ms"
    if value < 600.0:
        return f"{value:.3g} s"
    return f"{value:.4g} s ({value / 3600:.2g} h)"


def times(ratio: Any) -> str:
    """A speed-up or ratio, e.g. ``6850×``."""
    if not finite(ratio):
        return "n/a"
    return f"{ratio:,.0f}×" if ratio >= 1000 else f"{ratio:.3g}×"


def pct(fraction: Any, spec: str = ".3g") -> str:
    """A fraction as a percentage (without the % sign), or "n/a"."""
    return fmt(100 * fraction, spec) if finite(fraction) else "n/a"


def span(values: Any, spec: str = ".3g") -> str:
    """A ``[low, high]`` pair formatted, or n/a."""
    if not values or len(values) != 2 or not all(finite(v) for v in values):
        return "n/a"
    return f"[{values[0]:{spec}}, {values[1]:{spec}}]"


def yes(flag: Any) -> str:
    """The flag as yes, no or n/a."""
    return "n/a" if flag is None else ("yes" if flag else "no")


def esc(text: Any) -> str:
    """HTML-escaped text."""
    return html.escape(str(text))


def para(text: str, cls: str = "") -> str:
    """A paragraph of plain text (escaped)."""
    return f'<p class="{cls}">{esc(text)}</p>' if cls else f"<p>{esc(text)}</p>"


def h3(text: str) -> str:
    """A third-level heading (escaped)."""
    return f"<h3>{esc(text)}</h3>"


def table(header: Sequence[str], rows: Iterable[Sequence[Any]], highlight: Iterable[int] = (),
           table_id: str = "") -> str:
    """An HTML table of escaped cells; rows whose index is in ``highlight`` stand out."""
    marked = set(highlight)
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        cls = ' class="highlight"' if i in marked else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>")
    ident = f' id="{esc(table_id)}"' if table_id else ""
    return f"<table{ident}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def figure(src: str, alt: str, caption: str) -> str:
    """An image with its caption."""
    return (f'<figure><img src="{esc(src)}" alt="{esc(alt)}">'
            f"<figcaption>{esc(caption)}</figcaption></figure>")


def missing(what: str) -> str:
    """A note that an input file was not found."""
    return para(f"Not available: {what} was not found among the report's inputs.", "note")
