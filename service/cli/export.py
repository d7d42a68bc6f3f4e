"""``toftwin export``: our data in other tools' forms (issue 29).

``toftwin export calibration FILE --to opencv|ros --out FILE`` writes a calibration file's camera
(:func:`calibration.camera_forms.calibrated_intrinsics`: its lens keys, the pico flexx preset's
where it holds none) as OpenCV's FileStorage YAML or ROS's camera_info YAML
(:mod:`calibration.camera_forms`, docs/export.md).

``toftwin export frame DIR [DIR ...] --to hdf5|ply --out FILE`` writes frame folders as NeXus
HDF5 or a frame's valid pixels as a PLY point cloud (:mod:`service.cli.export_frame`,
docs/export-hdf5.md, docs/export-ply.md).

``toftwin export mitsuba SCENE --out DIR`` writes a scene as a Mitsuba 3 scene, ``DIR/scene.xml``
and its meshes as PLY files, which Mitsuba renders to the same DC image as ours
(:mod:`service.cli.export_mitsuba`, :mod:`sim_core.mitsuba_scene`, docs/export-mitsuba.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli.common import command_group, console, fail_invalid
from service.cli.out_files import check_out_file
from sim_core.errors import InvalidInputError

export_app = command_group("Our data in other tools' forms (NeXus HDF5, PLY, OpenCV, ROS, "
                           "Mitsuba 3).")


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
    camera_name: Annotated[str, typer.Option("--camera-name", help="ROS camera_name: 1-100 "
                                                                    "letters, digits or _.")] = (
        "pico_flexx"),
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --out.")] = False,
) -> None:
    """Write a calibration's camera in OpenCV's or ROS's calibration form."""
    import re

    from calibration.camera_forms import FORMS, ROS_CAMERA_NAME_PATTERN, write_camera_form
    from sim_core.twin_file import load_calibration

    try:
        if to not in FORMS:
            raise InvalidInputError("--to", f"{to!r}; allowed: {', '.join(FORMS)}")
        if not re.fullmatch(ROS_CAMERA_NAME_PATTERN, camera_name):
            raise InvalidInputError("--camera-name", f"{camera_name!r}: 1 to 100 letters, "
                                    "digits or underscores (what camera_info_manager takes)")
        _check_out(out, file, force)
        cal = load_calibration(file)
        try:
            path = write_camera_form(out, cal, to, camera_name)
        except OSError as exc:
            raise InvalidInputError("--out", f"'{out}' could not be written: "
                                    f"{exc.strerror or exc}") from None
    except InvalidInputError as exc:
        fail_invalid(exc)
    console.print(f"{to} calibration written to {path}")


def _check_out(out: Path, source: Path, force: bool) -> None:
    """Refuse an ``--out`` that is no calibration form to write (:func:`check_out_file`)."""
    check_out_file(out, [source], force, (".yml", ".yaml"), made_from="the calibration")


from service.cli.export_frame import export_frame  # noqa: E402
from service.cli.export_mitsuba import export_mitsuba  # noqa: E402

export_app.command("frame")(export_frame)
export_app.command("mitsuba")(export_mitsuba)
