"""What the operator page and the campaign report are made of: Jinja2 templates and the page's
static files (CSS, JavaScript), shipped in the package (no CDN: the lab may be offline).

:func:`environment` is the templates' environment, made by the project's one factory
(:func:`sim_core.html.jinja_environment`); the page (through FastAPI's ``Jinja2Templates``),
the API docs and the report use it, so they share their macros: a pose's image panels with
colour bars, its Table 5 rows, the difference the object twin explains.
"""

from __future__ import annotations

from pathlib import Path

import jinja2

from sim_core.html import jinja_environment

STATIC_DIR = Path(__file__).parent / "static"
#: where the templates are found: ``templates``, then ``static`` (the campaign report, one
#: self-contained file, inlines the stylesheet of a pose's figures the page links)
TEMPLATE_FOLDERS = ("templates", "static")


#: other packages' macros the templates import: calibration's verdict table (``_verdicts.html``)
SHARED_TEMPLATES = (("calibration", "templates"),)


def environment() -> jinja2.Environment:
    """The page's and the report's templates (``service/web/templates``, the page's static
    files for the report to inline, and :data:`SHARED_TEMPLATES`)."""
    return jinja_environment(__name__, TEMPLATE_FOLDERS, SHARED_TEMPLATES)
