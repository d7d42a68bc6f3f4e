"""The range a board pose predicts at every pixel (for the depth calibration)."""

from __future__ import annotations

import cv2
import numpy as np

from sim_core.camera import Intrinsics, pixel_centre_grid, pixel_to_camera_direction

#: pixels closer than this to the board's edge are left out (they mix board and background)
EDGE_MARGIN_PX = 2.5


def board_range_m(intrinsics: Intrinsics, rvec, tvec, extent_m: tuple[float, float]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Radial range (H, W) [m] to the board's plane, and the mask of pixels well inside it.

    ``rvec``, ``tvec``: OpenCV's pose of the board frame in the camera frame (board in its
    z = 0 plane, pattern over [0, W] x [0, H] = ``extent_m``). Pixel rays are the undistorted
    directions of the pixel centres; NaN where a ray misses the plane (behind the camera).
    """
    r = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    t = np.asarray(tvec, dtype=np.float64).ravel()
    u, v = pixel_centre_grid(intrinsics)
    d = pixel_to_camera_direction(intrinsics, u, v)
    n = r[:, 2]
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(np.abs(den) > 1e-9, (t @ n) / den, np.nan)
    s = np.where(s > 0, s, np.nan)
    hit = d * s[:, None]
    b = (hit - t) @ r  # board coordinates of the hit points
    margin = EDGE_MARGIN_PX * s / intrinsics.fx_px
    inside = ((b[:, 0] > margin) & (b[:, 0] < extent_m[0] - margin)
              & (b[:, 1] > margin) & (b[:, 1] < extent_m[1] - margin) & np.isfinite(s))
    return s.reshape(intrinsics.shape), inside.reshape(intrinsics.shape)
