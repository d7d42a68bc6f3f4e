"""What the operator page and the campaign report are made of: Jinja2 templates and the page's
static files (CSS, JavaScript), shipped in the package (no CDN: the lab may be offline).

:func:`environment` is the one Jinja2 environment both use (the page through FastAPI's
``Jinja2Templates``, the report directly), so they share their macros: a pose's image panels
with colour bars, its Table 5 rows, the object twin's verdict.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import jinja2

TEMPLATES_DIR = Path(__file__).parent / "templates"
STATIC_DIR = Path(__file__).parent / "static"


def _number(value: float | None, fmt: str = "{:.3g}", scale: float = 1.0) -> str:
    """A number for a table cell: ``-`` when there is none.

    >>> _number(None), _number(0.0123456), _number(0.012, "{:.1f}", 1e3)
    ('-', '0.0123', '12.0')
    """
    if value is None or not isinstance(value, int | float) or value != value:
        return "-"
    return fmt.format(value * scale)


@cache
def environment() -> jinja2.Environment:
    """The templates, HTML-escaped by default; filter ``number`` formats a cell."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES_DIR),
                             autoescape=jinja2.select_autoescape(("html",)),
                             undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True)
    env.filters["number"] = _number
    return env
