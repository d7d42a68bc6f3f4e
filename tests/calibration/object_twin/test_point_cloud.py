"""A measured view as points: ranges along the calibrated rays, depth errors removed, edges out."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.object_twin.point_cloud import cloud_from_phases, usable_pixels
from sim_core.camera import F_60_24_MHZ, Intrinsics, pixel_centre_grid, pixel_to_camera_direction
from sim_core.depth_errors import DepthErrorModel, range_to_phase_rad
from sim_core.twin_file import DepthErrors, WigglingTerm

INTR = Intrinsics(64, 48, 60.0, 61.0, 31.2, 23.7, (-0.1, 0.02, 0.001, -0.0005, 0.0))
FREQ = np.array([F_60_24_MHZ])


def _plane_ranges(z_m: float) -> np.ndarray:
    """Radial range of every pixel to the plane z = ``z_m`` (camera frame)."""
    u, v = pixel_centre_grid(INTR)
    d = pixel_to_camera_direction(INTR, u, v)
    return (z_m / d[:, 2]).reshape(INTR.shape)


def test_points_lie_on_the_plane_the_phases_say():
    rng = _plane_ranges(0.9)
    phase = range_to_phase_rad(rng, F_60_24_MHZ)[None]
    usable = np.ones(INTR.shape, dtype=bool)
    cloud = cloud_from_phases(phase, np.full(INTR.shape, 50.0), usable, FREQ, INTR, None, 0.0)
    # Every pixel but the image border (no neighbour there) becomes a point, at z = 0.9 m.
    assert cloud.n_points == (INTR.height_px - 2) * (INTR.width_px - 2)
    np.testing.assert_allclose(cloud.points_cam_m[:, 2], 0.9, atol=1e-9)


def test_depth_errors_are_removed_with_the_calibrations_model():
    rng = _plane_ranges(1.1)
    errors = DepthErrors(phase_offset_rad=[0.05],
                         wiggling=[WigglingTerm(harmonic=4, amplitude_rad=0.03, phase_rad=0.4)])
    model = DepthErrorModel.from_spec(errors, FREQ, INTR.shape)
    true_phase = range_to_phase_rad(rng, F_60_24_MHZ)[None]
    measured = true_phase + model.phase_error_rad(true_phase[0], 0)[None]
    usable = np.ones(INTR.shape, dtype=bool)
    raw = cloud_from_phases(measured, np.full(INTR.shape, 50.0), usable, FREQ, INTR, None, 0.0)
    fixed = cloud_from_phases(measured, np.full(INTR.shape, 50.0), usable, FREQ, INTR, model, 0.0)
    assert np.abs(raw.points_cam_m[:, 2] - 1.1).max() > 0.005  # the errors were there
    np.testing.assert_allclose(fixed.points_cam_m[:, 2], 1.1, atol=1e-6)


def test_flying_pixels_at_a_depth_step_and_flagged_pixels_are_dropped():
    rng = _plane_ranges(0.8)
    rng[:, 32:] = _plane_ranges(1.6)[:, 32:]  # a step: object in front of the background
    phase = range_to_phase_rad(rng, F_60_24_MHZ)[None]
    amp = np.full(INTR.shape, 40.0)
    valid = np.ones(INTR.shape, dtype=bool)
    valid[10, 10] = False  # the camera flagged it (saturated): amplitude above its threshold
    usable = usable_pixels(amp, valid)
    assert not usable[10, 10] and usable[11, 11]
    cloud = cloud_from_phases(phase, amp, usable, FREQ, INTR, None, 0.0)
    cols = cloud.pixels_rc[:, 1]
    assert not np.isin(cols, [31, 32]).any()  # both sides of the step
    assert not ((cloud.pixels_rc[:, 0] == 10) & (cols == 10)).any()
    z = cloud.points_cam_m[:, 2]
    assert np.all((np.abs(z - 0.8) < 1e-9) | (np.abs(z - 1.6) < 1e-9))


@pytest.mark.parametrize("amp, expected", [(5.0, False), (12.0, True)])
def test_dim_pixels_are_not_used(amp, expected):
    usable = usable_pixels(np.full((3, 3), amp), np.zeros((3, 3), dtype=bool))
    assert bool(usable[1, 1]) is expected


def test_the_calibrated_warm_up_drift_is_removed_at_the_captures_temperature():
    from calibration.captures import average_frames
    from calibration.object_twin.point_cloud import capture_cloud
    from sim_core.raw import RawFrame
    from sim_core.twin_file import CameraTemperature
    from sim_core.warmup import TemperatureDrift

    warm = CameraTemperature(illumination_start_c=25.0, illumination_end_c=45.0,
                             time_constant_s=600.0, depth_drift_mm_per_c=[0.8])
    drift = TemperatureDrift.from_spec(warm, FREQ)
    true_phase = range_to_phase_rad(_plane_ranges(1.0), F_60_24_MHZ)
    measured = true_phase + drift.phase_offset_rad(40.0)[0]  # 12 mm further at 40 degC
    c = np.stack([60.0 * np.cos(measured + k * np.pi / 2) for k in range(4)])[None]
    shape = INTR.shape
    frame = RawFrame(c, np.full(shape, 100.0), FREQ, np.zeros(shape, bool),
                     np.zeros(shape, bool), 500e-6, illumination_temperature_c=40.0)
    cap = average_frames([frame, frame])
    raw = capture_cloud(cap, INTR, None)
    fixed = capture_cloud(cap, INTR, None, temperature=warm)
    assert np.median(raw.points_cam_m[:, 2]) - 1.0 > 0.010  # the drift was there
    np.testing.assert_allclose(fixed.points_cam_m[:, 2], 1.0, atol=1e-6)
