"""The ``toftwin`` command line: one module per command group beside this one.

Exit codes: 0 success, 2 invalid input (the message names the field and the allowed range),
1 anything else.
"""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from service.cli import (
    calibrate,
    compare,
    correct,
    devices,
    fit_object,
    schema,
    serve,
    simulate,
)
from service.cli.bench import bench_app
from service.cli.common import command_group, print_error
from sim_core.errors import InvalidInputError

app = command_group("toftwin: hardware-in-the-loop twin of a PMD time-of-flight camera.",
                    add_completion=False)


def _print_version(value: bool) -> None:
    if value:
        from sim_core.frame_io import package_version

        typer.echo(f"toftwin {package_version()}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", is_eager=True, callback=_print_version,
                           help="Print the version of toftwin and exit.")
    ] = False,
) -> None:
    """toftwin: hardware-in-the-loop twin of a PMD time-of-flight camera."""


app.command("simulate")(simulate.simulate)
app.command("preview")(simulate.preview)
app.command("serve")(serve.serve)
app.command("compare")(compare.compare)
app.command("correct")(correct.correct)
app.add_typer(devices.devices_app, name="devices")
app.command("sim-device")(devices.sim_device)
app.add_typer(bench_app, name="bench")
app.add_typer(schema.schema_app, name="schema")
app.add_typer(calibrate.calibrate_app, name="calibrate")
app.command("fit-object")(fit_object.fit_object_command)


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except InvalidInputError as exc:  # pragma: no cover - commands catch their own
        print_error(str(exc))
        sys.exit(2)
