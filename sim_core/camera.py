"""Pinhole camera with OpenCV intrinsics and distortion, and the PMD CamBoard preset.

Conventions (ARCHITECTURE.md): the camera looks along +z, x to the right, y down; pixel
(u, v) = (column, row) with row 0 at the top; pixel centres at integer coordinates (OpenCV), so
for a 224 x 171 sensor the image centre is (111.5, 85.0).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from sim_core.errors import InvalidInputError

#: modulation frequencies of the CamBoard pico flexx use cases [Hz]
F_60_24_MHZ = 60.24e6
F_80_32_MHZ = 80.32e6


@dataclass(frozen=True)
class Intrinsics:
    """Pixel grid, focal lengths and OpenCV distortion (k1, k2, p1, p2, k3).

    Attributes
    ----------
    width_px, height_px : int
        Image size.
    fx_px, fy_px : float
        Focal lengths in pixels.
    cx_px, cy_px : float
        Principal point in OpenCV's pixel-centre convention.
    distortion : (5,) tuple of float
        k1, k2, p1, p2, k3 of OpenCV's radial-tangential model.
    """

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the images."""
        return (self.height_px, self.width_px)

    @property
    def has_distortion(self) -> bool:
        return any(abs(k) > 0.0 for k in self.distortion)

    def field_of_view_deg(self) -> tuple[float, float]:
        """Full horizontal and vertical field of view of the undistorted pinhole [deg]."""
        h = 2.0 * np.degrees(np.arctan(0.5 * self.width_px / self.fx_px))
        v = 2.0 * np.degrees(np.arctan(0.5 * self.height_px / self.fy_px))
        return float(h), float(v)


def distort_normalized(x: np.ndarray, y: np.ndarray, k: tuple[float, ...]) -> tuple:
    """Apply OpenCV's radial-tangential model to normalised image coordinates.

    Parameters
    ----------
    x, y : (n,) float
        Undistorted normalised coordinates (X/Z, Y/Z).
    k : (5,) float
        k1, k2, p1, p2, k3.
    """
    k1, k2, p1, p2, k3 = k
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


@njit(cache=True, inline="always", error_model="numpy")
def undistort_point(xd, yd, k1, k2, p1, p2, k3, iterations):
    """Invert :func:`distort_normalized` at one point by fixed-point iteration (compiled).

    The one implementation of the inversion: :func:`undistort_normalized` runs it over arrays
    and the render kernel's ``camera_ray`` inlines it.
    """
    x, y = xd, yd
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        # radial stays near 1 for physical lenses; the floor keeps a wild k from dividing by 0.
        if abs(radial) < 1e-6:
            radial = 1e-6
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    return x, y


@njit(cache=True, error_model="numpy")
def _undistort_points(xd, yd, k1, k2, p1, p2, k3, iterations):
    x = np.empty_like(xd)
    y = np.empty_like(yd)
    for i in range(xd.shape[0]):
        x[i], y[i] = undistort_point(xd[i], yd[i], k1, k2, p1, p2, k3, iterations)
    return x, y


def undistort_normalized(
    xd: np.ndarray, yd: np.ndarray, k: tuple[float, ...], iterations: int = 20
) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort_normalized` by fixed-point iteration (as cv2.undistortPoints).

    Converges for the moderate distortion of real lenses (|k1| r^2 well below 1); the result is
    checked by re-distorting in the tests. Runs :func:`undistort_point` on every point.
    """
    k1, k2, p1, p2, k3 = (float(v) for v in k)
    xa = np.asarray(xd, dtype=np.float64)
    ya = np.asarray(yd, dtype=np.float64)
    shape = np.broadcast_shapes(xa.shape, ya.shape)
    xa = np.ascontiguousarray(np.broadcast_to(xa, shape)).ravel()
    ya = np.ascontiguousarray(np.broadcast_to(ya, shape)).ravel()
    x, y = _undistort_points(xa, ya, k1, k2, p1, p2, k3, int(iterations))
    return x.reshape(shape), y.reshape(shape)


def pixel_to_camera_direction(
    intr: Intrinsics, u_px: np.ndarray, v_px: np.ndarray
) -> np.ndarray:
    """Unit ray directions in the camera frame through pixel coordinates ``(u, v)``.

    Parameters
    ----------
    u_px, v_px : (n,) float
        Column and row coordinates (pixel centres at integers).

    Returns
    -------
    (n, 3) float64 unit vectors with z > 0.
    """
    xd = (np.asarray(u_px, dtype=np.float64) - intr.cx_px) / intr.fx_px
    yd = (np.asarray(v_px, dtype=np.float64) - intr.cy_px) / intr.fy_px
    if intr.has_distortion:
        x, y = undistort_normalized(xd, yd, intr.distortion)
    else:
        x, y = xd, yd
    d = np.stack([x, y, np.ones_like(x)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d


def pixel_centre_grid(intr: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Flattened (u, v) coordinates of every pixel centre, row-major (row 0 first)."""
    v, u = np.mgrid[0 : intr.height_px, 0 : intr.width_px]
    return u.ravel().astype(np.float64), v.ravel().astype(np.float64)


def z_over_range(intr: Intrinsics) -> np.ndarray:
    """cos(alpha) of every pixel, (H, W): the z component of its pixel-centre ray's unit
    direction, i.e. ``depth_z / range`` (alpha: angle between the optical axis and the ray).

    Read-only and cached per intrinsics: every exposure needs it several times, and undistorting
    the whole grid costs more than the rest of the optics."""
    return _z_over_range(intr)


@functools.lru_cache(maxsize=16)
def _z_over_range(intr: Intrinsics) -> np.ndarray:
    u, v = pixel_centre_grid(intr)
    out = pixel_to_camera_direction(intr, u, v)[:, 2].reshape(intr.shape)
    out.flags.writeable = False
    return out


def range_to_depth_z(range_m: np.ndarray, z_over_range: np.ndarray) -> np.ndarray:
    """Depth along the optical axis from radial range: ``range * z_over_range``."""
    return range_m * z_over_range


def depth_z_to_range(depth_z_m: np.ndarray, z_over_range: np.ndarray) -> np.ndarray:
    """Radial range from depth along the optical axis: ``depth_z / z_over_range``."""
    return depth_z_m / z_over_range


def look_at(position_m, target_m, up) -> np.ndarray:
    """4x4 ``world_from_camera`` for a camera at ``position_m`` looking at ``target_m``.

    The camera's +z points at the target, +y (image down) is opposite to ``up`` projected on
    the image plane, +x completes a right-handed frame (image right).
    """
    p = np.asarray(position_m, dtype=np.float64)
    t = np.asarray(target_m, dtype=np.float64)
    up_v = np.asarray(up, dtype=np.float64)
    forward = t - p
    norm_f = np.linalg.norm(forward)
    if not np.isfinite(norm_f) or norm_f < 1e-12:
        raise InvalidInputError(
            "camera.pose.look_at_m",
            f"look-at target {t.tolist()} coincides with the camera position {p.tolist()}: "
            "the viewing direction has zero length; it must be at least 1e-12 m away",
        )
    z = forward / norm_f
    norm_up = np.linalg.norm(up_v)
    if not np.isfinite(norm_up) or norm_up < 1e-12:
        raise InvalidInputError("camera.pose.up", f"up vector {up_v.tolist()} has zero length")
    x = np.cross(z, up_v / norm_up)
    norm_x = np.linalg.norm(x)
    if norm_x < 1e-9:
        raise InvalidInputError(
            "camera.pose.up",
            f"up vector {up_v.tolist()} is parallel to the viewing direction {z.tolist()}; "
            "choose an up vector that is not",
        )
    x /= norm_x
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, p
    return m


@dataclass(frozen=True)
class Camera:
    """Everything the renderer and the sensor need to know about the camera.

    Attributes
    ----------
    intrinsics : Intrinsics
    world_from_camera : (4, 4) float64
        Rigid transform from the camera frame to the world frame.
    modulation_frequencies_hz : tuple of float
        One entry per frequency the camera measures at (two for the two-frequency mode).
    wavelength_m : float
        Centre wavelength of the active illumination and the band-pass filter.
    filter_band_m : (float, float)
        Pass band of the camera's filter, used for in-band ambient irradiance.
    aperture_diameter_m : float
        Entrance pupil diameter.
    exposure_s : float
        Exposure time per phase step.
    preset : str
        Name of the preset the camera came from.
    """

    intrinsics: Intrinsics
    world_from_camera: np.ndarray = field(repr=False)
    modulation_frequencies_hz: tuple[float, ...] = (F_60_24_MHZ,)
    wavelength_m: float = 850e-9
    filter_band_m: tuple[float, float] = (830e-9, 870e-9)
    aperture_diameter_m: float = 2e-3
    exposure_s: float = 500e-6
    preset: str = "custom"

    @property
    def position_m(self) -> np.ndarray:
        """Camera centre in world coordinates, (3,)."""
        return self.world_from_camera[:3, 3].copy()

    @property
    def rotation(self) -> np.ndarray:
        """3x3 rotation, world from camera."""
        return self.world_from_camera[:3, :3].copy()

    def pixel_directions_world(self, u_px: np.ndarray, v_px: np.ndarray) -> np.ndarray:
        """Unit ray directions in the world frame through pixel coordinates, (n, 3)."""
        d_cam = pixel_to_camera_direction(self.intrinsics, u_px, v_px)
        return d_cam @ self.rotation.T


#: Built-in camera presets: name -> keyword arguments of Intrinsics and Camera.
#: Sources in docs/camera-presets.md (issue of the seed's Table 2 and PMD's datasheet).
CAMERA_PRESETS: dict[str, dict] = {
    "pmd-camboard-pico-flexx": {
        "width_px": 224,
        "height_px": 171,
        "fx_px": 208.33,
        "fy_px": 208.33,
        "cx_px": 111.5,
        "cy_px": 85.0,
        "wavelength_m": 850e-9,
        "filter_band_m": (830e-9, 870e-9),
        "aperture_diameter_m": 2e-3,
        "exposure_s": 500e-6,
        "modulation_frequencies_hz": (F_60_24_MHZ,),
        "dual_frequency_hz": (F_80_32_MHZ, F_60_24_MHZ),
    },
}
