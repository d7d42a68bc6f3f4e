"""``toftwin export``: our data in other tools' forms (issue 29).

``toftwin export calibration FILE --to opencv|ros --out FILE`` writes a calibration file's camera
(:func:`calibration.camera_forms.calibrated_intrinsics`: its lens keys, the pico flexx preset's
where it holds none) as OpenCV's FileStorage YAML or ROS's camera_info YAML
(:mod:`calibration.camera_forms`, docs/export.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli.common import command_group, console, fail_invalid
from sim_core.errors import InvalidInputError

export_app = command_group("Our data in other tools' forms (OpenCV, ROS).")


@export_app.command("calibration")
def export_calibration(
    file: Annotated[Path, typer.Argument(help="Calibration file (YAML or JSON), any valid one: "
                                              "one holding only the intrinsics too.")],
    to: Annotated[str, typer.Option("--to", help="Form: opencv (FileStorage YAML: "
                                                 "camera_matrix, distortion_coefficients, "
                                                 "image_width, image_height) or ros "
                                                 "(camera_info YAML).")],
    out: Annotated[Path, typer.Option("--out", help="File to write (.yml/.yaml); an existing "
                                                    "one is refused unless --force.")],
    camera_name: Annotated[str, typer.Option("--camera-name", help="ROS camera_name.")] = (
        "pico_flexx"),
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --out.")] = False,
) -> None:
    """Write a calibration's camera in OpenCV's or ROS's calibration form."""
    from calibration.camera_forms import FORMS, write_camera_form
    from sim_core.twin_file import load_calibration

    try:
        if to not in FORMS:
            raise InvalidInputError("--to", f"{to!r}; allowed: {', '.join(FORMS)}")
        if out.suffix.lower() not in (".yml", ".yaml"):
            raise InvalidInputError("--out", f"'{out}': a .yml or .yaml file")
        if out.exists() and not force:
            raise InvalidInputError("--out", f"'{out}' exists; use --force to replace it")
        if not camera_name.strip() or len(camera_name) > 100:
            raise InvalidInputError("--camera-name", "1 to 100 characters")
        cal = load_calibration(file)
        path = write_camera_form(out, cal, to, camera_name)
    except InvalidInputError as exc:
        fail_invalid(exc)
    console.print(f"{to} calibration written to {path}")
