"""The physical ranges of a camera's intrinsics and distortion, for a given image size.

One home of the rules that scene files (``camera``), calibration and reality files
(``camera``) and so the CLI and the service apply when they parse a camera (issue 25): what
passes them renders without an exception or an overflow.

- **Focal lengths** (``fx_px`` with the image's width, ``fy_px`` with its height): the full
  field of view ``2 atan(n / (2 f))`` of ``n`` pixels at most :data:`MAX_FIELD_OF_VIEW_DEG`
  (170 deg: towards 180 the pinhole's ``tan`` and the ``cos^4`` fall-off lose all meaning), and
  a pixel at least :data:`MIN_PIXEL_ANGLE_RAD` wide (1e-9 rad: float64 ray directions still
  resolve a millionth of it, for the sub-pixel samples; the hard cases' telephoto views use
  1e-8). So ``f`` in ``[n / (2 tan 85 deg), 1e9]`` px; ``fx_px`` in [9.8, 1e9] for the pico
  flexx's 224 pixels and ``fy_px`` in [7.48, 1e9] for its 171.
- **Principal point**: inside the image, ``cx_px`` in ``[-0.5, width - 0.5]`` and ``cy_px`` in
  ``[-0.5, height - 0.5]`` (the image's outer pixel edges, pixel centres at integers).
- **Distortion** (OpenCV's k1, k2, p1, p2, k3): each coefficient within
  :data:`DISTORTION_LIMITS` (a guard of finite arithmetic: with the field of view above the
  normalised radius of the image stays below 23, and ``|k| r^6`` stays far from overflowing),
  and over the image the model must be a lens, not a fold: :func:`distortion_problem`.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from sim_core.camera import CAMERA_PRESETS, distort_normalized, undistort_normalized

#: largest full field of view along an image axis [deg]
MAX_FIELD_OF_VIEW_DEG = 170.0
#: smallest angle a pixel may subtend [rad]: the longest focal length is its inverse [px]
MIN_PIXEL_ANGLE_RAD = 1e-9
#: largest magnitude of each distortion coefficient
DISTORTION_LIMITS = {"k1": 100.0, "k2": 100.0, "p1": 1.0, "p2": 1.0, "k3": 100.0}
#: largest error of the renderer's inverse distortion at the image's points [px]
MAX_UNDISTORT_ERROR_PX = 0.01
#: iterations of the renderer's inverse distortion (``sim_core.render.kernels.camera_ray``)
RENDER_UNDISTORT_ITERATIONS = 20
#: the preset a calibration or reality file describes (its image size and defaults)
PRESET = CAMERA_PRESETS["pmd-camboard-pico-flexx"]


def focal_length_range_px(size_px: int) -> tuple[float, float]:
    """Focal lengths [px] that give ``size_px`` pixels at most the widest field of view, and
    each pixel at least the smallest angle.

    >>> [round(f, 2) for f in focal_length_range_px(224)]
    [9.8, 1000000000.0]
    """
    return (0.5 * size_px / math.tan(math.radians(MAX_FIELD_OF_VIEW_DEG / 2.0)),
            1.0 / MIN_PIXEL_ANGLE_RAD)


def focal_length_problem(value: float, size_px: int, side: str) -> str | None:
    """Why ``value`` [px] is no focal length for ``size_px`` pixels along ``side``, or None.

    >>> focal_length_problem(208.33, 224, "wide") is None
    True
    >>> print(focal_length_problem(1e-300, 224, "wide"))  # doctest: +NORMALIZE_WHITESPACE
    1e-300 px is outside [9.799, 1e+09] px: a 224 px wide image may see at most 170 deg, a
    pixel at least 1e-09 rad
    """
    lo, hi = focal_length_range_px(size_px)
    if math.isfinite(value) and lo <= value <= hi:
        return None
    return (f"{value:.6g} px is outside [{lo:.4g}, {hi:.4g}] px: a {size_px} px {side} image may "
            f"see at most {MAX_FIELD_OF_VIEW_DEG:g} deg, a pixel at least "
            f"{MIN_PIXEL_ANGLE_RAD:g} rad")


def principal_point_problem(value: float, size_px: int, side: str) -> str | None:
    """Why ``value`` [px] is no principal point coordinate in ``size_px`` pixels, or None.

    >>> print(principal_point_problem(300.0, 224, "wide"))
    300 px is outside [-0.5, 223.5] px: the principal point must lie inside the 224 px wide image
    """
    if math.isfinite(value) and -0.5 <= value <= size_px - 0.5:
        return None
    return (f"{value:.6g} px is outside [-0.5, {size_px - 0.5:g}] px: the principal point must "
            f"lie inside the {size_px} px {side} image")


def default_principal_point(width_px: int, height_px: int) -> tuple[float, float]:
    """The preset's principal point, or the image centre of a resized sensor."""
    if (width_px, height_px) == (PRESET["width_px"], PRESET["height_px"]):
        return PRESET["cx_px"], PRESET["cy_px"]
    return (width_px - 1) / 2.0, (height_px - 1) / 2.0


def _image_points(width_px: int, height_px: int, max_per_side: int = 65):
    """Pixel coordinates (u, v) covering the image to its outer pixel edges: a grid of at
    most ``max_per_side`` points per side and every border at a quarter of a pixel."""
    us = np.linspace(-0.5, width_px - 0.5, min(width_px + 1, max_per_side))
    vs = np.linspace(-0.5, height_px - 0.5, min(height_px + 1, max_per_side))
    u, v = (a.ravel() for a in np.meshgrid(us, vs))
    bu = np.linspace(-0.5, width_px - 0.5, 4 * width_px + 1)
    bv = np.linspace(-0.5, height_px - 0.5, 4 * height_px + 1)
    edge_u = np.concatenate([bu, bu, np.full_like(bv, -0.5), np.full_like(bv, width_px - 0.5)])
    edge_v = np.concatenate([np.full_like(bu, -0.5), np.full_like(bu, height_px - 0.5), bv, bv])
    return np.concatenate([u, edge_u]), np.concatenate([v, edge_v])


@functools.lru_cache(maxsize=256)
def distortion_problem(width_px: int, height_px: int, fx_px: float, fy_px: float,
                       cx_px: float, cy_px: float,
                       k: tuple[float, float, float, float, float]) -> str | None:
    """Why the distortion ``k`` (k1, k2, p1, p2, k3) is no lens over this image, or None.

    Over every point of the image (to its outer pixel edges):

    1. the renderer's inverse (:func:`sim_core.camera.undistort_normalized`, the fixed-point
       iteration its ray generation runs) converges: re-distorting its result gives the point
       back within :data:`MAX_UNDISTORT_ERROR_PX`;
    2. the radial model does not fold: with ``r`` up to the largest undistorted radius of the
       image, ``1 + k1 r^2 + k2 r^4 + k3 r^6 > 0`` (rays in front of the camera) and its
       derivative times ``r``, ``1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 > 0`` (one ray per point).
    """
    if not any(k):
        return None
    u, v = _image_points(width_px, height_px)
    xd, yd = (u - cx_px) / fx_px, (v - cy_px) / fy_px
    with np.errstate(all="ignore"):
        x, y = undistort_normalized(xd, yd, k, RENDER_UNDISTORT_ITERATIONS)
        finite = np.isfinite(x) & np.isfinite(y)
        if finite.all():
            xr, yr = distort_normalized(x, y, k)
            err_px = np.maximum(np.abs(xr - xd) * fx_px, np.abs(yr - yd) * fy_px)
            err_px = np.where(np.isfinite(err_px), err_px, np.inf)
        else:
            err_px = np.where(finite, 0.0, np.inf)
    worst = int(np.argmax(err_px))
    if not err_px[worst] <= MAX_UNDISTORT_ERROR_PX:
        return (f"{dict(zip(DISTORTION_LIMITS, k, strict=True))} cannot be inverted at pixel "
                f"({u[worst]:.1f}, {v[worst]:.1f}) of the {width_px} x {height_px} image (the "
                f"renderer's inverse is off by {err_px[worst]:.3g} px; allowed: "
                f"{MAX_UNDISTORT_ERROR_PX} px): the distortion is too strong for this field of "
                "view")
    r_max = float(np.sqrt(np.max(x * x + y * y)))
    k1, k2, _, _, k3 = k
    r2 = np.linspace(0.0, r_max, 2001) ** 2
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    slope = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
    bad = (radial <= 0.0) | (slope <= 0.0)
    if bad.any():
        r_fold = float(np.sqrt(r2[int(np.argmax(bad))]))
        return (f"k1 {k1:g}, k2 {k2:g}, k3 {k3:g} fold the image at normalised radius "
                f"{r_fold:.3g}, inside the image (it reaches {r_max:.3g}): "
                "1 + k1 r^2 + k2 r^4 + k3 r^6 and 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 must stay "
                "> 0 over the image")
    return None
