"""A measured view as a point cloud in the camera frame (issue 14, section 3).

The averaged capture's phase (the mean phasor's, :mod:`calibration.captures`) is corrected with
the calibration's depth-error model (:meth:`sim_core.depth_errors.DepthErrorModel.correct_phase`,
the inverse of what the camera adds), turned into a radial range (seed eq. 7) and placed along
each pixel's ray through the calibrated intrinsics and distortion
(:func:`sim_core.camera.pixel_to_camera_direction`).

Which pixels are kept:

- enough signal: the mean phasor's amplitude at least ``min_amplitude_dn``. The camera's own
  validity threshold (15 DN on one frame) is for single frames; an average of ``n`` frames has
  ``sqrt(n)`` less noise, so dimmer pixels still carry a usable phase;
- not flagged by the camera: a pixel above the camera's threshold that it still marks invalid
  is saturated or at the SBI limit (below the threshold the camera cannot say; with the solar
  simulator's shutter closed, as the object captures are taken, a dim pixel is not saturated);
- not at a depth edge: a pixel whose range differs from a neighbour's (8-neighbourhood) by more
  than ``edge_jump_m``, or that touches a dropped pixel, mixes two surfaces (a flying pixel at a
  silhouette, multipath in a corner) and is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from calibration.captures import AveragedCapture, drift_free_phase_rad
from sim_core.camera import Intrinsics, pixel_to_camera_direction
from sim_core.depth_errors import DepthErrorModel
from sim_core.errors import InvalidInputError
from sim_core.raw import ValidityThresholds
from sim_core.tof import ToFImage, range_from_phase, unwrap_two_frequencies
from sim_core.twin_file import CameraTemperature

#: default: least amplitude of an averaged pixel used as a point [DN]
MIN_AMPLITUDE_DN = 10.0
#: default: a range step to a neighbour beyond this marks a depth edge [m]
EDGE_JUMP_M = 0.05


@dataclass(frozen=True)
class ViewCloud:
    """The points of one view, in the camera frame.

    Attributes
    ----------
    turntable_angle_deg : float
        The angle the rig reported for the view.
    points_cam_m : (n, 3) float64
        Points in the camera frame (x right, y down, z forward) [m].
    pixels_rc : (n, 2) int
        Row and column of each point's pixel.
    amplitude_dn : (n,) float64
        The mean phasor's amplitude of each point's pixel [DN].
    usable : (H, W) bool
        Pixels with enough signal and not flagged (before the edge filter).
    kept : (H, W) bool
        Pixels that became points.
    """

    turntable_angle_deg: float
    points_cam_m: np.ndarray = field(repr=False)
    pixels_rc: np.ndarray = field(repr=False)
    amplitude_dn: np.ndarray = field(repr=False)
    usable: np.ndarray = field(repr=False)
    kept: np.ndarray = field(repr=False)

    @property
    def n_points(self) -> int:
        return int(self.points_cam_m.shape[0])


def range_from_phases(phase_rad: np.ndarray, frequencies_hz: np.ndarray) -> np.ndarray:
    """Radial range [m] from phases (n_f, H, W): one frequency, or the first two unwrapped."""
    f = np.asarray(frequencies_hz, dtype=np.float64).reshape(-1)
    if f.size >= 2:
        return unwrap_two_frequencies(phase_rad[0], f[0], phase_rad[1], f[1])
    return range_from_phase(phase_rad[0], f[0])


def depth_edges(range_m: np.ndarray, usable: np.ndarray, edge_jump_m: float) -> np.ndarray:
    """Pixels next to a range step above ``edge_jump_m`` or to an unusable pixel, (H, W) bool."""
    r = np.where(usable, range_m, np.nan)
    pad = np.pad(r, 1, constant_values=np.nan)
    h, w = r.shape
    edge = np.zeros((h, w), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == 0 and dc == 0:
                continue
            nb = pad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
            with np.errstate(invalid="ignore"):
                edge |= ~np.isfinite(nb) | (np.abs(nb - r) > edge_jump_m)
    return edge & usable


def cloud_from_phases(
    phase_rad: np.ndarray,
    amplitude_dn: np.ndarray,
    usable: np.ndarray,
    frequencies_hz: np.ndarray,
    intrinsics: Intrinsics,
    depth_model: DepthErrorModel | None,
    turntable_angle_deg: float,
    edge_jump_m: float = EDGE_JUMP_M,
) -> ViewCloud:
    """Points of the ``usable`` pixels that are not at a depth edge (module docstring).

    Parameters
    ----------
    phase_rad : (n_f, H, W) float
        Measured phases (with the camera's depth errors).
    amplitude_dn : (H, W) float
    usable : (H, W) bool
    frequencies_hz : (n_f,) float
    intrinsics : Intrinsics
        The calibrated intrinsics and distortion.
    depth_model : DepthErrorModel or None
        The calibration's depth errors (None: the phases are taken as true).
    turntable_angle_deg : float
    edge_jump_m : float
    """
    phase = np.asarray(phase_rad, dtype=np.float64)
    if phase.shape[-2:] != intrinsics.shape:
        raise InvalidInputError("capture", f"image {phase.shape[-2:]} does not match the "
                                f"calibrated camera's {intrinsics.shape}")
    if depth_model is not None:
        phase = depth_model.correct_phase(phase)
    rng = range_from_phases(phase, frequencies_hz)
    ok = usable & np.isfinite(rng) & (rng > 0.0)
    keep = ok & ~depth_edges(rng, ok, edge_jump_m)
    # Pixels that only survive as isolated specks are noise, not surface.
    keep = ndimage.binary_opening(keep, structure=np.ones((2, 2), dtype=bool))
    rows, cols = np.nonzero(keep)
    d = pixel_to_camera_direction(intrinsics, cols.astype(np.float64), rows.astype(np.float64))
    pts = d * rng[rows, cols][:, None]
    return ViewCloud(float(turntable_angle_deg), pts, np.stack([rows, cols], axis=1),
                     np.asarray(amplitude_dn, dtype=np.float64)[rows, cols], ok, keep)


def usable_pixels(amplitude_dn: np.ndarray, camera_valid: np.ndarray,
                  min_amplitude_dn: float = MIN_AMPLITUDE_DN) -> np.ndarray:
    """Enough signal and not flagged by the camera (saturation, SBI limit), (H, W) bool."""
    amp = np.asarray(amplitude_dn, dtype=np.float64)
    flagged = ~np.asarray(camera_valid, dtype=bool) & (
        amp >= ValidityThresholds().min_amplitude_dn)
    return (amp >= min_amplitude_dn) & ~flagged


def capture_cloud(
    capture: AveragedCapture,
    intrinsics: Intrinsics,
    depth_model: DepthErrorModel | None,
    min_amplitude_dn: float = MIN_AMPLITUDE_DN,
    edge_jump_m: float = EDGE_JUMP_M,
    temperature: CameraTemperature | None = None,
) -> ViewCloud:
    """The point cloud of an averaged capture (module docstring); ``temperature`` (the
    calibration's ``camera.temperature``) removes the warm-up drift at the capture's reported
    temperature, when it reports one."""
    usable = usable_pixels(capture.amplitude, capture.valid, min_amplitude_dn)
    # the warm-up drift acts after the depth errors (sim_core.pipeline): removed first
    return cloud_from_phases(drift_free_phase_rad(capture, temperature), capture.amplitude,
                             usable, capture.frequencies_hz, intrinsics, depth_model,
                             capture.turntable_angle_deg, edge_jump_m)


def image_cloud(
    image: ToFImage,
    intrinsics: Intrinsics,
    depth_model: DepthErrorModel | None,
    turntable_angle_deg: float,
    min_amplitude_dn: float = MIN_AMPLITUDE_DN,
    edge_jump_m: float = EDGE_JUMP_M,
) -> ViewCloud:
    """The point cloud of one reconstructed frame (its ``valid`` mask as the camera's flags)."""
    usable = usable_pixels(image.amplitude, image.valid, min_amplitude_dn) & image.valid
    return cloud_from_phases(image.phase_rad, image.amplitude, usable, image.frequencies_hz,
                             intrinsics, depth_model, turntable_angle_deg, edge_jump_m)
