"""The service's commands of the ``toftwin`` command line: one module per command group beside
this one.

:func:`build_app` assembles them; :mod:`toftwin_cli`, above the service, adds the command groups
that sit above it (``toftwin bench``) and is the console script. Exit codes: 0 success, 2 invalid
input (the message names the field and the allowed range), 1 anything else.
"""

from __future__ import annotations

from typing import Annotated

import typer

from service.cli import (
    calibrate,
    compare,
    correct,
    devices,
    export,
    fit_object,
    recordings,
    schema,
    serve,
    simulate,
)
from service.cli.common import command_group


def _print_version(value: bool) -> None:
    if value:
        from sim_core.frame_io import package_version

        typer.echo(f"toftwin {package_version()}")
        raise typer.Exit()


def _root(
    version: Annotated[
        bool, typer.Option("--version", is_eager=True, callback=_print_version,
                           help="Print the version of toftwin and exit.")
    ] = False,
) -> None:
    """toftwin: hardware-in-the-loop twin of a PMD time-of-flight camera."""


def build_app() -> typer.Typer:
    """A new ``toftwin`` app holding the service's commands; the caller may add command groups
    (:mod:`toftwin_cli` adds ``bench``)."""
    app = command_group("toftwin: hardware-in-the-loop twin of a PMD time-of-flight camera.",
                        add_completion=False)
    app.callback()(_root)
    app.command("simulate")(simulate.simulate)
    app.command("preview")(simulate.preview)
    app.command("serve")(serve.serve)
    app.command("compare")(compare.compare)
    app.command("correct")(correct.correct)
    app.add_typer(devices.devices_app, name="devices")
    app.command("sim-device")(devices.sim_device)
    app.command("camera-bridge")(devices.camera_bridge)
    app.add_typer(schema.schema_app, name="schema")
    app.add_typer(calibrate.calibrate_app, name="calibrate")
    app.command("fit-object")(fit_object.fit_object_command)
    app.command("record")(recordings.record_command)
    app.command("replay")(recordings.replay_command)
    app.add_typer(export.export_app, name="export")
    return app


#: the service's commands (the whole ``toftwin`` command is :data:`toftwin_cli.app`)
app = build_app()
