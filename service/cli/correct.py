"""``toftwin correct``: remove a calibration's depth errors from a measured frame folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli.common import console, fail_invalid
from sim_core.errors import InvalidInputError


def correct(
    frame_dir: Annotated[Path, typer.Argument(help="Measured frame folder (raw.npz).")],
    calibration: Annotated[Path, typer.Option("--calibration", help="Calibration file.")],
    out: Annotated[
        Path | None, typer.Option("--out", help="Output folder (default FRAME_DIR-corrected).")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing output.")] = False,
) -> None:
    """Write a copy of FRAME_DIR with the camera's depth errors removed."""
    import shutil

    from calibration.correction import correct_frame
    from sim_core.twin_file import load_calibration

    target = out or frame_dir.with_name(frame_dir.name + "-corrected")
    try:
        cal = load_calibration(calibration)
        if target.exists():
            if not force:
                raise InvalidInputError("--out", f"'{target}' exists; use --force to replace it")
            if target.resolve() != frame_dir.resolve():
                shutil.rmtree(target)
        correct_frame(frame_dir, cal, target)
    except InvalidInputError as exc:
        fail_invalid(exc)
    console.print(f"corrected frame written to {target}")
