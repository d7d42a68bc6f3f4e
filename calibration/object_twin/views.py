"""Where a captured view puts the camera: the scene as captured, the mount frame of each view.

The object twin works in the *mount frame*: the world frame with the turntable at its zero, in
which the reality's mount offset is defined (:class:`sim_core.twin_file.MountParameters`). A
view's camera-frame points reach it through the camera's pose (the scene's nominal pose: the
calibration absorbs a mount error of the camera into its intrinsics and axis,
docs/calibration.md) and the inverse turntable rotation about the calibrated axis by the true
angle (reported angle + calibrated zero offset).
"""

from __future__ import annotations

import numpy as np

from calibration.captures import AveragedCapture
from sim_core.camera import Camera
from sim_core.errors import InvalidInputError
from sim_core.geometry import axis_angle_matrix
from sim_core.scene import build_camera
from sim_core.scene_spec import SceneSpec
from sim_core.twin_apply import apply_to_spec, true_turntable_deg
from sim_core.twin_file import TwinParameters


def capture_spec(spec: SceneSpec, capture: AveragedCapture) -> SceneSpec:
    """``spec`` with its camera set to the capture's use case (frequencies, exposure, size)."""
    h, w = capture.shape
    camera = spec.camera.model_copy(update={
        "modulation_frequencies_hz": [float(f) for f in capture.frequencies_hz],
        "exposure_s": float(capture.exposure_s),
        "width_px": int(w),
        "height_px": int(h),
    })
    return spec.model_copy(update={"camera": camera})


def calibrated_camera(spec: SceneSpec, calibration: TwinParameters | None) -> Camera:
    """The camera as calibrated: its intrinsics and distortion, at the scene's pose."""
    return build_camera(apply_to_spec(spec, calibration or TwinParameters()))


def mount_from_camera(spec: SceneSpec, calibration: TwinParameters | None,
                      reported_deg: float) -> np.ndarray:
    """4x4 transform from a view's camera frame to the mount frame (module docstring).

    Raises
    ------
    InvalidInputError
        If the scene has no turntable (nothing is mounted).
    """
    twin = calibration or TwinParameters()
    cal_spec = apply_to_spec(spec, twin)
    tt = cal_spec.turntable
    if tt is None:
        raise InvalidInputError("spec.turntable", "the scene has no turntable: no mount to fit")
    angle_rad = np.radians(true_turntable_deg(float(reported_deg), twin))
    r = axis_angle_matrix(tt.axis_direction, -angle_rad)
    c = np.asarray(tt.axis_point_m, dtype=np.float64)
    undo = np.eye(4)
    undo[:3, :3] = r
    undo[:3, 3] = c - r @ c
    return undo @ build_camera(cal_spec).world_from_camera
