"""``toftwin serve``: the REST service (uvicorn) on the rig or the simulated lab.

Every setting is validated, and the data directory checked to be free, before anything is
written (the session token of a simulated rig included).
"""

from __future__ import annotations

import logging
import os
import secrets
from pathlib import Path
from typing import Annotated

import typer

from service.cli import ranges
from service.cli.common import err_console, number_option, print_error, print_warning
from service.store.data_lock import make_private

#: the settings the options of ``serve`` set: field -> option
OPTION_OF_FIELD = {"host": "--host", "port": "--port", "data_dir": "--data-dir",
                   "simulated": "--simulated", "executor": "--executor", "workers": "--workers",
                   "faults": "--fault", "reality": "--reality", "camera": "--camera",
                   "camera_mode": "--camera-mode"}


def serve(
    host: Annotated[str | None, typer.Option(help="Address to bind (default 127.0.0.1).")] = None,
    port: Annotated[
        int | None, number_option("--port", help="TCP port (default 8000; 0: any free port).",
                                  allowed=ranges.PORT)
    ] = None,
    data_dir: Annotated[
        Path | None,
        typer.Option("--data-dir", help="Frames and database (default ./toftwin-data)."),
    ] = None,
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Run on the device simulators.")
    ] = False,
    executor: Annotated[
        str | None, typer.Option(help="local (process pool), thread, or dask://HOST:PORT.")
    ] = None,
    workers: Annotated[
        int | None, number_option("--workers", help="Local executor workers.",
                                  allowed=ranges.WORKERS)
    ] = None,
    settings_file: Annotated[
        Path | None, typer.Option("--settings", help="Settings file (dotenv, TOFTWIN_* keys).")
    ] = None,
    log_level: Annotated[str, typer.Option(help="debug, info, warning, error.")] = "info",
    fault: Annotated[
        list[str] | None,
        typer.Option("--fault", help="Arm a fault on a simulated device (repeatable): "
                     "DEVICE:name[:count][@skip], DEVICE turntable, solar-simulator or camera, "
                     "e.g. solar-simulator:lamp-fault:1@6. Needs --simulated."),
    ] = None,
    reality: Annotated[
        Path | None,
        typer.Option("--reality", help="The simulated lab's reality file (how its world differs "
                     "from the nominal scene; docs/calibration.md). Needs --simulated."),
    ] = None,
    camera: Annotated[
        str | None,
        typer.Option("--camera", help="usb (default), royale (PMD's roypy in this process) or "
                     "a camera bridge tcp://HOST:PORT (toftwin-camera-bridge beside the camera; "
                     "with --simulated, toftwin camera-bridge --simulated)."),
    ] = None,
    camera_mode: Annotated[
        str | None,
        typer.Option("--camera-mode", help="raw (default: royale's raw frames, reconstructed "
                     "by toftwin) or depth (royale's processed depth and grey, for a camera "
                     "without raw access; --camera royale or a bridge)."),
    ] = None,
) -> None:
    """Start the REST API (uvicorn); --simulated runs on the simulators and the satellite scene."""
    import uvicorn

    from service.api.app import create_app
    from service.cli.command_settings import load_settings

    # A simulated rig started without a token gets a session token; it is written only once
    # every setting is known to be valid and the data directory free (a refused start writes
    # nothing, and a running server's token stays).
    session = (simulated and "TOFTWIN_TOKEN" not in os.environ and settings_file is None)
    token = secrets.token_urlsafe(24) if session else None
    given = {"host": host, "port": port, "data_dir": data_dir, "simulated": simulated or None,
             "executor": executor, "workers": workers, "faults": fault or None,
             "reality": reality, "camera": camera, "camera_mode": camera_mode}
    settings = load_settings(settings_file, OPTION_OF_FIELD, token=token, **given)
    refuse_if_in_use(settings.data_dir)
    refuse_if_no_room(settings.data_dir)
    if session:
        session_token(settings.data_dir, token)
    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    if settings.host not in ("127.0.0.1", "localhost", "::1"):
        print_warning(f"listening on {settings.host}, not loopback")
    try:
        uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                    log_level=log_level.lower())
    except SystemExit as exc:
        if exc.code not in (0, None):  # start-up failed: another service took the lock since?
            refuse_if_in_use(settings.data_dir)
        raise


def refuse_if_in_use(data_dir: Path) -> None:
    """Exit with code 2, naming the holder, if another process holds ``data_dir``.

    The lock itself is taken by :func:`service.lab.lab.open_lab` at start-up, inside uvicorn's
    lifespan, where a refusal would only be a logged traceback and uvicorn's exit code 3; this
    check makes the usual case (a second ``toftwin serve`` on the same directory) a one-line
    error before anything (the session token file included) is written.
    """
    from service.store.data_lock import DataDirInUseError, DataDirLock

    try:
        DataDirLock.check(data_dir)
    except DataDirInUseError as exc:
        print_error(str(exc))
        raise typer.Exit(code=2) from None


#: the room SQLite needs to open the database (its shared-memory index and write-ahead log)
#: when the data directory holds no reserve to give back for it [bytes]
OPEN_ROOM_BYTES = 1024 * 1024


def refuse_if_no_room(data_dir: Path) -> None:
    """Exit with code 2 if the data directory's disk has no room to open the database.

    On a full disk the service still starts and serves reads by giving back its reserve
    (``DATA_DIR/.space-reserve``) while SQLite opens; without one (deleted, or released by a
    delete on the full disk) SQLite cannot open its log, and the start would end in uvicorn's
    traceback. This says so in a sentence, with the sizes, before anything is written.
    """
    from service.lab.lab import RESERVE_NAME
    from service.store.disk_space import format_bytes, free_bytes

    existing = Path(data_dir).resolve()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    free = free_bytes(existing)
    if free >= OPEN_ROOM_BYTES or (Path(data_dir) / RESERVE_NAME).is_file():
        return
    print_error(f"the data directory's disk is full: {format_bytes(free)} free, and opening the "
                f"database needs about {format_bytes(OPEN_ROOM_BYTES)} (the directory holds no "
                f"{RESERVE_NAME} to give back for it); free some space (old frames or other "
                "files on that disk) and start again")
    raise typer.Exit(code=2)


#: open flag that refuses a symlink as the last path component (0 where the OS has none)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)


def session_token(data_dir: Path, token: str | None = None) -> str:
    """A bearer token (``token``, or a new random one) for a simulated service started without
    one.

    Written to ``DATA_DIR/token`` (mode 0600) and printed once, so that the first command of the
    README works on a fresh machine without a placeholder secret; a real rig needs TOFTWIN_TOKEN.
    """
    make_private(data_dir)
    path = data_dir / "token"
    token = token or secrets.token_urlsafe(24)
    try:  # never through a symlink (it could point anywhere), and 0600 even if it existed
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | _NOFOLLOW, 0o600)
    except OSError as exc:
        print_error(f"cannot write the session token to {path}: {exc.strerror} (a symlink is "
                    "refused); remove it or set TOFTWIN_TOKEN")
        raise typer.Exit(code=2) from None
    with os.fdopen(fd, "w") as fh:
        os.fchmod(fh.fileno(), 0o600)
        fh.write(token + "\n")
    err_console.print(f"simulated rig: no TOFTWIN_TOKEN given, this session's token is in {path}",
                      soft_wrap=True)
    return token
