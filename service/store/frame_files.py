"""The frame store: one folder per frame under ``<data_dir>/frames/``, written atomically.

A frame is written into ``frames/.partial-<id>/`` (each file itself written to a temporary name
and renamed by :mod:`sim_core.frame_io`), then the folder is renamed to ``frames/<id>/`` and the
parent directory is fsynced: a reader sees a whole frame or none. The database row naming the
frame is committed afterwards, with the result that uses it; :meth:`FrameStore.sweep` removes
what a crash left between the two (partial folders, folders without a row).

Layout of a frame folder (the same as ``toftwin simulate --out``):

- simulated: ``frame.npz``, ``frame.json``, ``grey.png``, ``depth.png`` and ``raw.npz`` (from
  :func:`sim_core.pipeline.save_frame`);
- measured: ``raw.npz`` as the camera delivered it, and ``frame.npz``/``frame.json``/PNGs of its
  reconstruction (:func:`sim_core.raw.reconstruct_raw`), ``frame.json`` holding the rig state
  and the intrinsics used.
"""

from __future__ import annotations

import os
import re
import shutil
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from sim_core import frame_io
from sim_core.camera import Camera
from sim_core.pipeline import ARRAY_UNITS, package_version
from sim_core.raw import RawFrame, ValidityThresholds, reconstruct_raw
from sim_core.sensor import SensorParams
from sim_core.tof import ToFImage

FRAME_ID = re.compile(r"^[0-9a-f]{32}$")
#: the files of a frame folder (``save_frame`` layout)
SIMULATED_FILES = ("frame.npz", "frame.json", "grey.png", "depth.png", "raw.npz")
_PARTIAL = ".partial-"


def new_frame_id() -> str:
    """A fresh frame id (32 hex digits)."""
    return uuid.uuid4().hex


def measured_arrays(image: ToFImage, grey_full_scale: float | None) -> dict[str, np.ndarray]:
    """The ``frame.npz`` arrays of a reconstructed measured frame (names as simulated frames)."""
    grey, _ = frame_io.grey_preview_8bit(image.amplitude, image.valid, grey_full_scale)
    return {
        "grey_8bit": grey,
        "depth_mm": frame_io.depth_preview_mm(image.range_m),
        "range_m": image.range_m,
        "depth_z_m": image.depth_z_m,
        "amplitude": image.amplitude,
        "intensity": image.intensity,
        "phase_rad": image.phase_rad[0],
        "phase_all_rad": image.phase_rad,
        "valid": image.valid,
        "frequencies_hz": image.frequencies_hz,
    }


def intrinsics_dict(camera: Camera) -> dict[str, Any]:
    """The intrinsics of ``camera`` as stored in a measured frame's ``frame.json``."""
    i = camera.intrinsics
    return {
        "width_px": i.width_px, "height_px": i.height_px, "fx_px": i.fx_px, "fy_px": i.fy_px,
        "cx_px": i.cx_px, "cy_px": i.cy_px, "distortion": list(i.distortion),
    }


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
    ) -> tuple[str, ToFImage]:
        """Reconstruct and write a measured frame; returns its id and the reconstruction.

        The reconstruction uses ``camera`` (the scene's intrinsics at the use case's size) for
        the range-to-depth conversion; ``extra`` goes into ``frame.json``.
        """
        from sim_core.optics import cos_off_axis

        if raw.shape != camera.intrinsics.shape:
            raise ValueError(
                f"measured frame is {raw.shape}, the camera model {camera.intrinsics.shape}"
            )
        image = reconstruct_raw(raw, cos_off_axis(camera))
        full_scale = float(2 ** (SensorParams().adc_bits - 1))
        arrays = measured_arrays(image, full_scale)
        frame_id = new_frame_id()
        meta = {
            "kind": "measured",
            "frame_id": frame_id,
            "package_version": package_version(),
            "shape": list(image.range_m.shape),
            "frequencies_hz": image.frequencies_hz.tolist(),
            "exposure_s": raw.exposure_s,
            "timestamp_s": raw.timestamp_s,
            "grey_preview_full_scale": full_scale,
            "intrinsics": intrinsics_dict(camera),
            "validity": ValidityThresholds().to_dict(),
            "camera_meta": raw.meta,
            "arrays": {k: ARRAY_UNITS[k] for k in arrays},
            **extra,
        }

        def write(d: Path) -> None:
            raw.save(d / "raw.npz")
            frame_io.write_npz(d / "frame.npz", arrays)
            frame_io.write_png(d / "depth.png", arrays["depth_mm"])
            frame_io.write_png(d / "grey.png", arrays["grey_8bit"])
            frame_io.write_json(d / "frame.json", meta)

        self._publish(frame_id, write)
        return frame_id, image

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
