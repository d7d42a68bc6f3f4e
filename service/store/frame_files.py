"""The frame store: one folder per frame under ``<data_dir>/frames/``, written atomically.

A frame is written into ``frames/.partial-<id>/`` (each file itself written to a temporary name
and renamed by :mod:`sim_core.frame_io`), then the folder is renamed to ``frames/<id>/`` and the
parent directory is fsynced (:func:`sim_core.files.fsync_dir`): a reader sees a whole frame or
none. The database row naming the frame is committed afterwards, with the result that uses it;
:meth:`FrameStore.sweep` removes what a crash left between the two (partial folders, folders
without a row).

The layout of a frame folder (the same as ``toftwin simulate --out``) is the frame format of
:mod:`sim_core.frame_io` (docs/frame-format.md), which writes and reads every file of it.

A file can still go bad on disk afterwards (a disk error, a copy cut short, someone's editor):
reads go through :meth:`FrameStore.read`, :meth:`FrameStore.checked_file` and
:meth:`FrameStore.metadata`, which answer a file that is gone with :class:`GoneError` and one
that cannot be read with :class:`DamagedFileError`, both naming the frame and the file by its
place inside the data directory (``frames/<id>/raw.npz``, never the server's absolute path).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from service.errors import DamagedFileError, GoneError
from service.store.disk_space import SpaceReserve
from sim_core import frame_io
from sim_core.camera import Camera
from sim_core.files import fsync_dir
from sim_core.processed_depth import ProcessedDepthFrame
from sim_core.raw import RawFrame
from sim_core.tof import ToFImage

FRAME_ID = re.compile(r"^[0-9a-f]{32}$")
#: the files of a frame folder (:data:`sim_core.frame_io.FRAME_FILES`)
SIMULATED_FILES = frame_io.FRAME_FILES
#: the files a folder that does not read is searched for the damaged one: a measured folder of
#: royale's processed depth keeps ``depth_points.npz`` instead of ``raw.npz`` (a file that is
#: not there is no damage)
DIAGNOSED_FILES = (*SIMULATED_FILES, frame_io.DEPTH_POINTS_NPZ)
_PARTIAL = ".partial-"


def new_frame_id() -> str:
    """A fresh frame id (32 hex digits)."""
    return uuid.uuid4().hex


_READ_ERRORS = frame_io.FRAME_READ_ERRORS


def file_damage(path: Path) -> str | None:
    """Why the frame file ``path`` cannot be read (None: it reads whole).

    ``.npz``: every array decompresses (its CRC checks); ``.json``: a JSON object; ``.png``: an
    image whose chunks check and whose pixels decode.
    """
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                for key in z.files:
                    z[key]
        elif path.suffix == ".json":
            if not isinstance(json.loads(path.read_bytes()), dict):
                return "it holds no JSON object"
        elif path.suffix == ".png":
            with Image.open(path) as im:
                im.verify()
            with Image.open(path) as im:
                im.load()
    except FileNotFoundError:
        return None
    except (*_READ_ERRORS, Image.DecompressionBombError) as exc:
        kind = {".npz": "a complete npz archive", ".json": "valid JSON",
                ".png": "a complete PNG image"}.get(path.suffix, "readable")
        return f"it is not {kind} ({type(exc).__name__}: truncated or corrupt)"
    return None


class FrameStore:
    """Frames as folders under ``root``; ``reserve``: the disk reserve that deletes release
    (:class:`service.store.disk_space.SpaceReserve`; None: none kept)."""

    def __init__(self, root: str | Path, reserve: SpaceReserve | None = None) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.reserve = reserve

    def path(self, frame_id: str) -> Path:
        """Folder of a frame; raises ``KeyError`` for an id of the wrong form."""
        if not FRAME_ID.match(frame_id):
            raise KeyError(frame_id)
        return self.root / frame_id

    def where(self, frame_id: str, name: str | None = None) -> str:
        """A frame's folder or file as a place inside the data directory (no server path)."""
        return f"{self.root.name}/{frame_id}" + ("" if name is None else f"/{name}")

    def file(self, frame_id: str, name: str) -> Path:
        """The path of one of a frame's files; 410 naming the frame and the file (relative to
        the data directory: never the server's path) if it is not on disk."""
        path = self.path(frame_id) / name
        if not path.is_file():
            where = "the frame's folder is gone" if not path.parent.is_dir() else f"{name} is gone"
            raise GoneError(f"frame {frame_id}: {where} from the data directory "
                            f"({self.where(frame_id, name)}); its database row remains")
        return path

    def damaged(self, frame_id: str, name: str, why: str) -> DamagedFileError:
        """The 410 of a frame file that is there but cannot be read."""
        return DamagedFileError(
            f"frame file damaged: {name} of frame {frame_id} ({self.where(frame_id, name)} in "
            f"the data directory): {why}; its database row remains, delete it or restore the "
            "file")

    def checked_file(self, frame_id: str, name: str) -> Path:
        """:meth:`file`, after checking that the file reads whole (else 410 naming it)."""
        path = self.file(frame_id, name)
        why = file_damage(path)
        if why is not None:
            raise self.damaged(frame_id, name, why)
        return path

    def metadata(self, frame_id: str) -> dict[str, Any]:
        """The frame's ``frame.json`` ({} if it has none; 410 if it cannot be read)."""
        path = self.path(frame_id) / frame_io.FRAME_JSON
        if not path.is_file():
            return {}
        why = file_damage(path)
        if why is not None:
            raise self.damaged(frame_id, frame_io.FRAME_JSON, why)
        return json.loads(path.read_bytes())

    def read(self, frame_id: str) -> frame_io.Frame:
        """The frame (:func:`sim_core.frame_io.read_frame`); 410 naming the frame and the file
        if the folder is gone or a file of it cannot be read."""
        folder = self.path(frame_id)
        if not folder.is_dir():
            self.file(frame_id, frame_io.FRAME_JSON)  # the GoneError naming the folder
        try:
            return frame_io.read_frame(folder)
        except _READ_ERRORS as exc:
            for name in DIAGNOSED_FILES:  # which file: the first that does not read whole
                why = file_damage(folder / name)
                if why is not None:
                    raise self.damaged(frame_id, name, why) from exc
            raise DamagedFileError(
                f"frame {frame_id} ({self.where(frame_id)} in the data directory) cannot be "
                f"read: {type(exc).__name__}; its database row remains") from exc

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
        fsync_dir(self.root)
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
        self, raw: RawFrame | ProcessedDepthFrame, camera: Camera, extra: dict[str, Any]
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

    @contextlib.contextmanager
    def room_to_delete(self) -> Iterator[None]:
        """The block (a delete) runs with the disk reserve given back (if one is kept); it is
        made again afterwards, room permitting (:class:`SpaceReserve`)."""
        if self.reserve is None:
            yield
            return
        with self.reserve.released():
            yield

    def delete(self, frame_ids: Iterable[str]) -> None:
        """Remove frames (a deleted campaign's or frame's; those of a result that could not be
        committed)."""
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
