"""Applying a calibration (or the simulated lab's reality) to a scene.

:func:`apply_to_spec` rewrites the parts of a :class:`~sim_core.scene_spec.SceneSpec` the file
measures (intrinsics, distortion, sensor, source power, turntable axis, and for a twin with the
object keys - a reality, a calibration combined with an object file - the mount's pose);
:func:`sim_core.scene.build_scene` then applies the rest at pose time (turntable zero, solar
scale, per-object reflectance, depth errors), see :mod:`sim_core.twin_file` for the
conventions.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from sim_core import lens_ranges
from sim_core.errors import SceneError
from sim_core.geometry import rotation_matrix_xyz_deg
from sim_core.materials import Material
from sim_core.scene_spec import CameraSpec, ObjectPose, SceneSpec, scene_error_from_validation
from sim_core.twin_file import ObjectTwinParameters, TwinParameters, has_object_keys

#: material parameters that scale with reflectance (``objects.<name>.reflectance_scale``)
REFLECTANCE_FIELDS = ("albedo", "kd", "ks", "w")


def apply_to_spec(spec: SceneSpec, twin: TwinParameters) -> SceneSpec:
    """The scene as the twin parameters say the rig really is (the static parts).

    >>> from sim_core.twin_file import parse_calibration
    >>> camera = {"pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}}
    >>> spec = SceneSpec.model_validate({"camera": camera})
    >>> cal = parse_calibration({"camera": {"fx_px": 211.4}, "illumination": {"power_w": 1.3}})
    >>> out = apply_to_spec(spec, cal)
    >>> out.camera.fx_px, out.illumination.power_w
    (211.4, 1.3)
    """
    cam = twin.camera
    image = (spec.camera.width_px or lens_ranges.PRESET["width_px"],
             spec.camera.height_px or lens_ranges.PRESET["height_px"])
    if cam.image_size_px is not None and tuple(cam.image_size_px) != image:
        w, h = cam.image_size_px
        raise SceneError("camera.image_size_px", f"the calibration's lens was measured on a "
                         f"{w} x {h} image; this scene's camera is {image[0]} x {image[1]}: "
                         "it is another camera's calibration")
    cam_update = {k: getattr(cam, k) for k in ("fx_px", "fy_px", "cx_px", "cy_px", "distortion")
                  if getattr(cam, k) is not None}
    sensor_set = cam.sensor.model_dump(exclude_none=True)
    if sensor_set:
        cam_update["sensor"] = spec.camera.sensor.model_copy(update=sensor_set)
    update: dict = {}
    if cam_update:
        update["camera"] = _checked_camera(spec.camera.model_copy(update=cam_update))
    if twin.illumination.power_w is not None:
        update["illumination"] = spec.illumination.model_copy(
            update={"power_w": twin.illumination.power_w})
    tt = twin.turntable
    if spec.turntable is not None and (tt.axis_point_m is not None
                                       or tt.axis_direction is not None):
        tt_update = {k: getattr(tt, k) for k in ("axis_point_m", "axis_direction")
                     if getattr(tt, k) is not None}
        update["turntable"] = spec.turntable.model_copy(update=tt_update)
    if has_object_keys(twin):
        objects = _mounted_objects(spec, twin)
        if objects is not None:
            update["objects"] = objects
    return spec.model_copy(update=update) if update else spec


def _checked_camera(camera: CameraSpec) -> CameraSpec:
    """``camera`` validated again: the twin's intrinsics checked against the scene's image (a
    file checks them against the preset's; a scene may resize the sensor)."""
    try:
        return CameraSpec.model_validate(camera.model_dump())
    except ValidationError as exc:
        err = scene_error_from_validation(exc)
        raise SceneError(f"camera.{err.field}", f"{err.message} (the calibration's value on "
                         "this scene's camera)") from None


def _mounted_objects(spec: SceneSpec, reality: ObjectTwinParameters):
    """The objects with the mount's pose offset applied to those on the turntable (or None)."""
    off = reality.mount.pose_offset
    if off == ObjectPose() or spec.turntable is None:
        return None
    r_off = rotation_matrix_xyz_deg(off.rotation_deg)
    t_off = np.asarray(off.position_m, dtype=np.float64)
    # The nominal axis point: the mount sits on the turntable as the scene says it does.
    c = np.asarray(spec.turntable.axis_point_m, dtype=np.float64)
    out = []
    for obj in spec.objects:
        if not obj.on_turntable:
            out.append(obj)
            continue
        r = r_off @ rotation_matrix_xyz_deg(obj.pose.rotation_deg)
        p = c + r_off @ (np.asarray(obj.pose.position_m) - c) + t_off
        angles = Rotation.from_matrix(r).as_euler("xyz", degrees=True)
        pose = ObjectPose(position_m=tuple(float(v) for v in p),
                          rotation_deg=tuple(float(v) for v in angles))
        out.append(obj.model_copy(update={"pose": pose}))
    return out


def true_turntable_deg(reported_deg: float, twin: TwinParameters | None) -> float:
    """True angle = reported angle + the twin's zero offset [deg]."""
    return reported_deg + (twin.turntable.zero_offset_deg if twin is not None else 0.0)


def true_suns(set_suns: float | None, twin: TwinParameters | None) -> float | None:
    """True solar level = set level x the twin's irradiance scale [sun] (None stays None)."""
    if set_suns is None or twin is None:
        return set_suns
    return set_suns * twin.solar_simulator.irradiance_scale


def scale_reflectance(material: Material, scale: float) -> Material:
    """``material`` with its reflectance parameters times ``scale``, clipped to [0, 1]."""
    changes = {f: float(np.clip(getattr(material, f) * scale, 0.0, 1.0))
               for f in REFLECTANCE_FIELDS if hasattr(material, f)}
    return dataclasses.replace(material, **changes) if changes else material
