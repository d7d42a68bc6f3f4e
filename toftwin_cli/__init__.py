"""The ``toftwin`` command: the service's commands (:func:`service.cli.build_app`) and the
benchmarks' ``bench`` group (:data:`benchmarks.cli.bench_app`), assembled above both.

The console script and ``python -m toftwin_cli`` run :func:`main`. Exit codes: 0 success,
2 invalid input (the message names the field and the allowed range), 1 anything else.
"""

from __future__ import annotations

import sys

from benchmarks.cli import bench_app
from service.cli import build_app
from service.cli.common import print_error
from sim_core.errors import InvalidInputError

app = build_app()
app.add_typer(bench_app, name="bench")


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except InvalidInputError as exc:  # pragma: no cover - commands catch their own
        print_error(str(exc))
        sys.exit(2)
