"""``toftwin devices``, ``toftwin sim-device`` and ``toftwin camera-bridge``: what is connected,
simulators to try, and the camera served to a service elsewhere."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from typing import Annotated

import typer

from drivers.diagnostics import check_devices, list_devices
from service.cli import ranges
from service.cli.common import (
    command_group,
    console,
    fail_invalid,
    number_option,
    print_error,
)
from sim_core.errors import InvalidInputError

devices_app = command_group("Devices of the rig: list and check them.")


@contextlib.contextmanager
def _simulated_ports() -> Iterator[dict]:
    """Serial simulators on pseudo-terminals and a simulated USB camera, for ``--simulated``."""
    from drivers.sim.pty_server import start_simulator
    from drivers.sim.usb_camera import UsbCameraSim

    with start_simulator("turntable", [], instant=True) as tt, \
            start_simulator("solar-simulator", [], instant=True) as solar:
        lamp, shutter = solar.ports
        yield {"usb_backend": UsbCameraSim(), "turntable_port": tt.ports[0],
               "lamp_port": lamp, "shutter_port": shutter, "probe_camera_wire": True}


@devices_app.command("list")
def list_cmd(
    simulated: bool = typer.Option(False, "--simulated", help="List the simulated camera."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of text."),
) -> None:
    """PMD cameras on USB, with serial number, product, USB speed and accessibility."""
    backend = None
    if simulated:
        from drivers.sim.usb_camera import UsbCameraSim

        backend = UsbCameraSim()
    found = list_devices(backend)
    if as_json:
        console.print_json(json.dumps(found))
        return
    if not found:
        console.print("no PMD camera (USB vendor 0x1C28) found")
    for d in found:
        console.print(", ".join(f"{k}: {v}" for k, v in d.items()), markup=False)


@devices_app.command("check")
def check_cmd(
    simulated: bool = typer.Option(False, "--simulated", help="Check against the simulators."),
    turntable_port: str | None = typer.Option(None, help="SMC100 serial port."),
    turntable_address: Annotated[
        int, number_option("--turntable-address", help="SMC100 address.",
                           allowed=ranges.TURNTABLE_ADDRESS)
    ] = 1,
    lamp_port: str | None = typer.Option(None, help="Oriel lamp supply port."),
    shutter_port: str | None = typer.Option(None, help="Oriel exposure controller port."),
    camera_serial: str | None = typer.Option(None, help="Which camera (default: first)."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of text."),
) -> None:
    """Talk to every device and report ok / warning / error with a fix; exit 1 on error."""
    with contextlib.ExitStack() as stack:
        if simulated:
            kw = stack.enter_context(_simulated_ports())
        else:
            kw = {"turntable_port": turntable_port, "lamp_port": lamp_port,
                  "shutter_port": shutter_port}
        report = check_devices(turntable_address=turntable_address,
                               camera_serial=camera_serial, **kw)
    if as_json:
        console.print_json(json.dumps(report.to_dict()))
    else:
        console.print(str(report), markup=False, highlight=False)
    if not report.ok:
        raise typer.Exit(code=1)


def sim_device(
    kind: str = typer.Argument(..., help="turntable or solar-simulator"),
    fault: Annotated[
        list[str] | None, typer.Option("--fault", help="Fault to inject: name[:count][@skip].")
    ] = None,
    transport: str = typer.Option("pty", help="pty (a pseudo-terminal) or tcp (socket://)."),
    instant: bool = typer.Option(False, "--instant", help="Moves and warm-up finish at once."),
) -> None:
    """Serve one serial device simulator; prints its port first, serves until stopped.

    Only the port paths go to stdout (a script reads them); every error goes to stderr.
    """
    from drivers.sim.pty_server import serve
    from service.cli.common import choice

    try:
        choice("KIND", kind, ("turntable", "solar-simulator"))
        choice("--transport", transport, ("pty", "tcp"))
        serve(kind, list(fault or []), transport=transport, instant=instant)
    except InvalidInputError as exc:
        fail_invalid(exc)


def camera_bridge(
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Serve the simulated camera (it films the "
                           "simulated world of the service that connects; a plane at 1 m "
                           "until then).")
    ] = False,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[
        int, number_option("--port", help="TCP port (0: any free port).", allowed=ranges.PORT)
    ] = 5600,
    access_code: Annotated[
        str | None, typer.Option("--access-code", help="royale's access code (level 2: raw "
                                 "data before royale 5; else $TOFTWIN_ROYALE_ACCESS_CODE).")
    ] = None,
) -> None:
    """Serve the camera to a toftwin service elsewhere (``serve --camera tcp://HOST:PORT``).

    Prints ``tcp://HOST:PORT`` first (a script reads it) and serves until stopped. Without
    --simulated it opens a pico flexx with PMD's roypy, as the one-file
    ``toftwin_camera_bridge.py`` does on a lab PC.
    """
    import signal
    import threading

    from toftwin_camera_bridge import BridgeError, BridgeServer, RoyaleSource, import_roypy

    if simulated:
        from drivers.sim.bridge_source import SimulatedCameraSource
        from drivers.sim.usb_camera import plane_source

        def make_source(on_frame):
            return SimulatedCameraSource(on_frame, plane_source(1.0), paced=True)
    else:
        try:
            roypy = import_roypy()
        except BridgeError as exc:
            print_error(str(exc))
            raise typer.Exit(code=1) from exc

        def make_source(on_frame):
            return RoyaleSource(roypy, on_frame, access_code)

    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    server = BridgeServer(make_source, host, port).start()
    try:
        print(f"tcp://{server.address[0]}:{server.address[1]}", flush=True)
        while not stop.wait(0.2):
            pass
    finally:
        server.close()
