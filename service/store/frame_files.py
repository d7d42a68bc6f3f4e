"""The frame store: one folder per frame under ``<data_dir>/frames/``, written atomically.

A frame is written into ``frames/.partial-<id>/`` (each file itself written to a temporary name
and renamed by :mod:`sim_core.frame_io`), then the folder is renamed to ``frames/<id>/`` and the
parent directory is fsynced: a reader sees a whole frame or none. The database row naming the
frame is committed afterwards, with the result that uses it; :meth:`FrameStore.sweep` removes
what a crash left between the two (partial folders, folders without a row).

The layout of a frame folder (the same as ``toftwin simulate --out``) is the frame format of
:mod:`sim_core.frame_io` (docs/frame-format.md), which writes and reads every file of it.
"""

from __future__ import annotations

import os
import re
import shutil
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from service.errors import GoneError
from sim_core import frame_io
from sim_core.camera import Camera
from sim_core.raw import RawFrame
from sim_core.tof import ToFImage

FRAME_ID = re.compile(r"^[0-9a-f]{32}$")
#: the files of a frame folder (:data:`sim_core.frame_io.FRAME_FILES`)
SIMULATED_FILES = frame_io.FRAME_FILES
_PARTIAL = ".partial-"


def new_frame_id() -> str:
    """A fresh frame id (32 hex digits)."""
    return uuid.uuid4().hex


class FrameStore:
    """Frames as folders under ``root``."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def path(self, frame_id: str) -> Path:
        """Folder of a frame; raises ``KeyError`` for an id of the wrong form."""
        if not FRAME_ID.match(frame_id):
            raise KeyError(frame_id)
        return self.root / frame_id

    def file(self, frame_id: str, name: str) -> Path:
        """The path of one of a frame's files; 410 naming the frame and the file (relative to
        the data directory: never the server's path) if it is not on disk."""
        path = self.path(frame_id) / name
        if not path.is_file():
            where = "the frame's folder is gone" if not path.parent.is_dir() else f"{name} is gone"
            raise GoneError(f"frame {frame_id}: {where} from the data directory "
                            f"({self.root.name}/{frame_id}/{name}); its database row remains")
        return path

    def exists(self, frame_id: str) -> bool:
        return FRAME_ID.match(frame_id) is not None and (self.root / frame_id).is_dir()

    def _publish(self, frame_id: str, write) -> Path:
        tmp = self.root / f"{_PARTIAL}{frame_id}"
        tmp.mkdir()
        try:
            write(tmp)
            final = self.root / frame_id
            os.replace(tmp, final)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        _fsync_dir(self.root)
        return final

    def save_files(self, frame_id: str, files: dict[str, bytes]) -> Path:
        """Publish a frame whose files were written elsewhere (a simulation worker)."""
        for name in files:
            if name not in SIMULATED_FILES:
                raise ValueError(f"unexpected frame file {name!r}; allowed: {SIMULATED_FILES}")

        def write(d: Path) -> None:
            for name, data in files.items():
                with open(d / name, "wb") as fh:
                    fh.write(data)
                    fh.flush()
                    os.fsync(fh.fileno())

        return self._publish(frame_id, write)

    def save_measured(
        self, raw: RawFrame, camera: Camera, extra: dict[str, Any]
    ) -> tuple[str, ToFImage, float]:
        """Reconstruct and write a measured frame (:func:`sim_core.frame_io.write_measured`).

        The reconstruction uses ``camera`` (the scene's intrinsics at the use case's size) for
        the range-to-depth conversion; ``extra`` goes into ``frame.json``. Returns the frame's
        id, the reconstruction and its grey full scale.
        """
        if raw.shape != camera.intrinsics.shape:
            raise ValueError(
                f"measured frame is {raw.shape}, the camera model {camera.intrinsics.shape}"
            )
        frame_id = new_frame_id()
        out: dict[str, Any] = {}

        def write(d: Path) -> None:
            out["image"], out["full_scale"] = frame_io.write_measured(
                d, raw, camera, {"frame_id": frame_id, **extra}
            )

        self._publish(frame_id, write)
        return frame_id, out["image"], out["full_scale"]

    def delete(self, frame_ids: Iterable[str]) -> None:
        """Remove frames (used when a result could not be committed)."""
        for fid in frame_ids:
            if FRAME_ID.match(fid):
                shutil.rmtree(self.root / fid, ignore_errors=True)

    def sweep(self, known_ids: set[str]) -> list[str]:
        """Delete partial folders and frames no database row names; returns what was removed."""
        removed = []
        for p in self.root.iterdir():
            if p.name.startswith(_PARTIAL) or (
                p.is_dir() and FRAME_ID.match(p.name) and p.name not in known_ids
            ):
                shutil.rmtree(p, ignore_errors=True)
                removed.append(p.name)
        return removed


def _fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` durable (POSIX: fsync the directory)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # e.g. Windows: directories cannot be opened; rename is durable enough
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
