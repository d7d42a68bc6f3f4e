"""``toftwin export frame DIR [DIR ...] --to hdf5|ply --out FILE``: frame folders in the field's
forms (docs/export-hdf5.md, docs/export-ply.md).

One folder as a NeXus HDF5 file (:func:`sim_core.nexus.write_frame_nexus`) or as a PLY point
cloud of its valid pixels (:func:`sim_core.frame_points.write_points_ply`, in the camera frame
or, where frame.json holds the pose, the world frame); several folders as one NeXus file with
the frames stacked along a frame axis (:class:`sim_core.nexus.NexusFrameStack`), in the order
given.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from service.cli.common import console, fail_invalid
from service.cli.out_files import check_out_file
from sim_core.errors import InvalidInputError

#: the forms and the suffixes their files take
FRAME_FORMS = {"hdf5": (".h5", ".hdf5", ".nxs"), "ply": (".ply",)}


def export_frame(
    folders: Annotated[list[Path], typer.Argument(
        help="Frame folder(s) (toftwin simulate --out, the service's frames/<id>); several "
             "make one HDF5 file with a frame axis.")],
    to: Annotated[str, typer.Option("--to", help="Form: hdf5 (NeXus: NXdata with axes and "
                                                 "units) or ply (point cloud, one folder).")],
    out: Annotated[Path, typer.Option("--out", help="File to write (.h5/.hdf5/.nxs or .ply); "
                                                    "an existing one is refused unless "
                                                    "--force.")],
    point_frame: Annotated[str, typer.Option("--frame", help="ply: camera (x right, y down, z "
                                                             "forward) or world (needs the "
                                                             "pose in frame.json).")] = "camera",
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --out.")] = False,
) -> None:
    """Write frame folders as NeXus HDF5 or a frame as a PLY point cloud."""
    from sim_core.frame_points import POINT_FRAMES, write_points_ply
    from sim_core.nexus import NexusFrameStack, write_frame_nexus

    try:
        if to not in FRAME_FORMS:
            raise InvalidInputError("--to", f"{to!r}; allowed: {', '.join(FRAME_FORMS)}")
        if point_frame not in POINT_FRAMES:
            raise InvalidInputError("--frame", f"{point_frame!r}; allowed: "
                                    f"{', '.join(POINT_FRAMES)}")
        if to == "ply" and len(folders) != 1:
            raise InvalidInputError("folders", f"{len(folders)} given; a PLY holds one frame")
        for folder in folders:
            _check_folder(folder)
        check_out_file(out, [], force, FRAME_FORMS[to])
        out.parent.mkdir(parents=True, exist_ok=True)
        if to == "ply":
            n = write_points_ply(out, _read(folders[0]), point_frame)  # type: ignore[arg-type]
            console.print(f"{n} points ({point_frame} frame) written to {out}")
            return
        if len(folders) == 1:
            write_frame_nexus(out, _read(folders[0]))
        else:  # into a temporary file beside --out, renamed when every frame is in
            fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
            os.close(fd)
            try:
                with NexusFrameStack(tmp) as stack:
                    for folder in folders:  # one frame in memory at a time
                        stack.append(_read(folder))
                os.replace(tmp, out)
            finally:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(tmp)
    except InvalidInputError as exc:
        fail_invalid(exc)
    console.print(f"{len(folders)} frame{'s' if len(folders) > 1 else ''} written to {out} "
                  "(NeXus HDF5)")


def _check_folder(folder: Path) -> None:
    """Refuse what is no frame folder: not a folder, or one with none of a frame's arrays."""
    from sim_core.frame_io import DEPTH_POINTS_NPZ, FRAME_NPZ, RAW_NPZ

    if not folder.is_dir():
        raise InvalidInputError("folders", f"'{folder}' is not a frame folder")
    if not any((folder / n).is_file() for n in (FRAME_NPZ, RAW_NPZ, DEPTH_POINTS_NPZ)):
        raise InvalidInputError("folders", f"'{folder}' is not a frame folder: it holds none "
                                f"of {FRAME_NPZ}, {RAW_NPZ}, {DEPTH_POINTS_NPZ}")


def _read(folder: Path):
    """The frame of ``folder``; a file of it that cannot be read is an input error naming the
    folder and the reason (a truncated or corrupt archive, a frame.json out of its form)."""
    from sim_core.frame_io import FRAME_READ_ERRORS, read_frame

    try:
        return read_frame(folder)
    except InvalidInputError as exc:
        raise InvalidInputError("folders", f"'{folder}': {exc.field}: {exc.message}") from None
    except FRAME_READ_ERRORS as exc:
        raise InvalidInputError("folders", f"'{folder}' cannot be read: {type(exc).__name__}: "
                                f"{exc} (a truncated or corrupt file?)") from None
