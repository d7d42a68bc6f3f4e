"""The one way an HTML page is made: a Jinja2 environment over a package's templates folder.

Every page of the project comes from :func:`jinja_environment`: the operator page, its
fragments, the API docs and the campaign report (``service.web``'s templates) and the
calibration's ``report.html`` (``calibration``'s). They share its rules: every ``{{ value }}``
HTML-escaped (a campaign named ``<script>`` shows as text), an undefined name an error rather
than an empty cell, block tags without their trailing newline, and the same filters
(:data:`FILTERS`). It lives here, at the bottom of the packages, so calibration (below the
service) uses the same one.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any

import jinja2


def number(value: Any, fmt: str = "{:.3g}", scale: float = 1.0) -> str:
    """A number for a table cell: ``-`` when there is none (``None``, not a number, NaN).

    >>> number(None), number(0.0123456), number(0.012, "{:.1f}", 1e3), number(float("nan"))
    ('-', '0.0123', '12.0', '-')
    """
    if value is None or not isinstance(value, int | float) or value != value:
        return "-"
    return fmt.format(value * scale)


#: the filters every template may use: ``{{ x | number("{:.1f} %", 100) }}``
FILTERS: dict[str, Callable[..., str]] = {"number": number}


@cache
def jinja_environment(package: str, folders: tuple[str, ...] = ("templates",),
                      shared: tuple[tuple[str, str], ...] = ()) -> jinja2.Environment:
    """The environment of the templates in ``folders`` of ``package`` (shipped as package data;
    a name is looked up in the folders in turn, then in the ``(package, folder)`` pairs of
    ``shared``: another package's macros, e.g. calibration's verdict table), made once per
    arguments: autoescape on for every template, :class:`jinja2.StrictUndefined`,
    ``trim_blocks`` and ``lstrip_blocks``, the filters of :data:`FILTERS`."""
    loader = jinja2.ChoiceLoader([jinja2.PackageLoader(package, f) for f in folders]
                                 + [jinja2.PackageLoader(p, f) for p, f in shared])
    env = jinja2.Environment(loader=loader, autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True)
    env.filters.update(FILTERS)
    return env
