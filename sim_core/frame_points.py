"""A frame's valid pixels as a point cloud, and the cloud as a PLY file (docs/export-ply.md).

Each valid pixel with a finite range becomes the point ``range * d(u, v)`` in the camera frame
(x right, y down, z along the optical axis, metres), ``d`` the unit direction of its
pixel-centre ray through the frame's intrinsics, distortion included
(:func:`sim_core.camera.pixel_to_camera_direction`): the same ray the range was measured or
rendered along. Where ``frame.json`` holds the pose (``world_from_camera``: a simulated frame
records its camera's), the points can be given in the scene's world frame too.

Per point the PLY carries the pixel's column and row, its grey level (``grey.png``) and a noise
estimate [m]: the local robust spread of the range's second differences
(:func:`sim_core.flying_pixels.second_difference_noise_m`) over sqrt(6), which for independent
Gaussian range noise of standard deviation sigma estimates sigma. It needs no sensor model and
so means the same for a measured and a simulated frame; at an edge or on a curved surface the
scene's own shape adds to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from sim_core.camera import pixel_to_camera_direction
from sim_core.errors import InvalidInputError
from sim_core.files import atomic_write
from sim_core.flying_pixels import second_difference_noise_m
from sim_core.frame_io import Frame, image_intrinsics, intrinsics_known, pose_from_meta

#: second differences of independent range noise of standard deviation sigma have sqrt(6) sigma
#: (1 + 4 + 1 times its variance)
SECOND_DIFFERENCE_PER_SIGMA = math.sqrt(6.0)

PointFrame = Literal["camera", "world"]
POINT_FRAMES: tuple[PointFrame, ...] = ("camera", "world")


@dataclass(frozen=True)
class FramePoints:
    """The valid pixels of a frame as points.

    Attributes
    ----------
    xyz_camera_m : (n, 3) float64
        Points in the camera frame [m].
    column_px, row_px : (n,) int
        The pixel each point comes from.
    grey : (n,) uint8
        The frame's grey level at the pixel.
    noise_m : (n,) float64
        Local range-noise estimate [m] (NaN where the image has no second difference).
    intrinsics_known : bool
        Whether frame.json records the intrinsics the points were made with (else the pico
        flexx preset's, with the principal point at the image centre).
    world_from_camera : (4, 4) float64 or None
        The frame's pose, where known.
    """

    xyz_camera_m: np.ndarray
    column_px: np.ndarray
    row_px: np.ndarray
    grey: np.ndarray
    noise_m: np.ndarray
    world_from_camera: np.ndarray | None
    intrinsics_known: bool = True

    def xyz_m(self, frame: PointFrame = "camera") -> np.ndarray:
        """The points in the camera frame, or in the world frame (the pose must be known)."""
        if frame not in POINT_FRAMES:
            raise InvalidInputError("--frame", f"{frame!r}; allowed: {', '.join(POINT_FRAMES)}")
        if frame == "camera":
            return self.xyz_camera_m
        if self.world_from_camera is None:
            raise InvalidInputError(
                "--frame", "world: this frame's frame.json holds no world_from_camera (its pose "
                "is not known); use camera")
        r, t = self.world_from_camera[:3, :3], self.world_from_camera[:3, 3]
        return self.xyz_camera_m @ r.T + t


def frame_points(frame: Frame) -> FramePoints:
    """The points of ``frame``'s valid pixels with a finite, positive range."""
    im = frame.image
    rng = np.asarray(im.range_m, dtype=np.float64)
    keep = np.asarray(im.valid, dtype=bool) & np.isfinite(rng) & (rng > 0.0)
    rows, cols = np.nonzero(keep)
    intr = image_intrinsics(frame.meta, rng.shape)
    directions = pixel_to_camera_direction(intr, cols.astype(np.float64), rows.astype(np.float64))
    noise = second_difference_noise_m(rng, keep) / SECOND_DIFFERENCE_PER_SIGMA
    return FramePoints(
        xyz_camera_m=directions * rng[rows, cols][:, None],
        column_px=cols, row_px=rows, grey=frame.grey_8bit()[rows, cols],
        noise_m=noise[rows, cols], world_from_camera=pose_from_meta(frame.meta),
        intrinsics_known=intrinsics_known(frame.meta))


def ply_bytes(points: FramePoints, frame: PointFrame = "camera") -> bytes:
    """Binary little-endian PLY of ``points`` (trimesh): vertices x, y, z [m] in ``frame``,
    properties ``column``, ``row`` (uint16), ``grey`` (uint8), ``noise_m`` (float32), and
    comments saying the frame and the units."""
    xyz = points.xyz_m(frame)
    mesh = trimesh.Trimesh(vertices=xyz, faces=np.empty((0, 3), dtype=np.int64), process=False)
    mesh.vertex_attributes["column"] = points.column_px.astype(np.uint16)
    mesh.vertex_attributes["row"] = points.row_px.astype(np.uint16)
    mesh.vertex_attributes["grey"] = points.grey.astype(np.uint8)
    mesh.vertex_attributes["noise_m"] = points.noise_m.astype(np.float32)
    data = mesh.export(file_type="ply", encoding="binary")
    comments = (f"comment toftwin point cloud: x y z in metres, {frame} frame"
                + (" (x right, y down, z along the optical axis)" if frame == "camera" else
                   " (the scene's world, via frame.json's world_from_camera)")
                + "\ncomment grey: the frame's grey level; noise_m: local range-noise estimate\n"
                + ("" if points.intrinsics_known else "comment intrinsics: the pico flexx "
                   "preset's (the frame records none)\n"))
    first = data.index(b"\n", data.index(b"format")) + 1  # after the format line
    return data[:first] + comments.encode("ascii") + data[first:]


def write_points_ply(path: str | Path, frame: Frame, point_frame: PointFrame = "camera") -> int:
    """Write ``frame``'s points as a PLY file (atomically); returns the point count."""
    points = frame_points(frame)
    data = ply_bytes(points, point_frame)  # refuses the world frame without a pose first
    atomic_write(Path(path), data)
    return int(points.xyz_camera_m.shape[0])
