"""The twin's reference for each view of the sweep: the same plate as a Lambertian of known albedo.

The twin (the calibration applied: intrinsics, distortion, gain, source power and profile,
turntable axis and zero, solar scale) renders the sample plate at the reported angle as a
Lambertian of albedo ``rho``. A Lambertian reflects ``rho / pi`` per steradian, so wherever the
sensor responds linearly the measured over the reference signal times ``rho / pi`` is the
sample's BRDF for that pixel's directions: everything else (the source's power and angular
profile, inverse-square, the camera's response and optics) is the same in both and cancels.

The solar simulator's light adds to the intensity linearly until SBI starts (seed section
2.2.3): from then on the intensity no longer grows with it. The reference is exposed without the
solar light, with a little of it (:data:`SOLAR_SCALE_LINEAR` times the set level: the linear
response per unit of scale) and with a great deal (:data:`SOLAR_SCALE_SBI`: the intensity at
which SBI holds the pixel); pixels measured near that intensity are left out
(:mod:`calibration.rig_material.slices`).

The pixels' geometry comes from the same render (:class:`PlateGeometry`): the plate's pixels
away from its outline, their points, normals, and the directions to the camera's source, to the
camera and to the solar simulator, in each pixel's shading frame (normal +z).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy import ndimage

from calibration.rig_material.plan import SAMPLE_NAME, MaterialSweepPlan
from calibration.twin_prediction import predict_view
from sim_core.materials import frame_from_normal, to_local
from sim_core.scene import Scene
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import TwinParameters

#: ambient scale (times the set level) of the linear response: small enough that no pixel
#: reaches SBI (a Lambertian of albedo ``rho`` at scale ``s`` looks like albedo ``s rho``)
SOLAR_SCALE_LINEAR = 0.05
#: ambient scale at which every lit pixel is held by SBI: its intensity there is SBI's level
SOLAR_SCALE_SBI = 100.0


@dataclasses.dataclass(frozen=True)
class PlateGeometry:
    """The plate's usable pixels and their directions in each pixel's shading frame.

    Attributes
    ----------
    mask : (H, W) bool
        Plate pixels at least ``edge_margin_px`` from its outline.
    to_source : (n, 3) float64
        Unit directions from each pixel's surface point to the camera's source (shading frame,
        normal +z; ``n`` = pixels of ``mask`` in row-major order).
    to_camera : (n, 3) float64
        ... to the camera's centre.
    to_sun : (n, 3) float64 or None
        ... towards the solar simulator (against its beam), when the scene has one.
    """

    mask: np.ndarray
    to_source: np.ndarray
    to_camera: np.ndarray
    to_sun: np.ndarray | None


@dataclasses.dataclass(frozen=True)
class ReferenceView:
    """The twin's reference plate at one reported turntable angle.

    Attributes
    ----------
    turntable_angle_deg : float
        The reported angle.
    albedo : float
        The reference Lambertian's albedo.
    amplitude_dn : (H, W) float64
        Noise-free amplitude with the camera's source alone [DN].
    range_m : (H, W) float64
        Noise-free measured range the twin predicts (its depth errors included) [m].
    solar_slope_dn : (H, W) float64 or None
        Linear response of the intensity to the solar simulator: the intensity it adds at the
        set level, extrapolated from :data:`SOLAR_SCALE_LINEAR` (SBI left aside) [DN].
    sbi_intensity_dn : (H, W) float64 or None
        Intensity at which SBI holds the pixel [DN]: beyond about this the intensity stops
        responding to the solar simulator.
    geometry : PlateGeometry
    """

    turntable_angle_deg: float
    albedo: float
    amplitude_dn: np.ndarray
    range_m: np.ndarray
    solar_slope_dn: np.ndarray | None
    sbi_intensity_dn: np.ndarray | None
    geometry: PlateGeometry


def reference_view(spec: SceneSpec, base_dir: str | Path, twin: TwinParameters,
                   turntable_deg: float, plan: MaterialSweepPlan, seed: int = 0) -> ReferenceView:
    """Render and expose the reference plate (``spec`` holds it, as a Lambertian of
    ``plan.reference_albedo``, named :data:`SAMPLE_NAME`) at a reported angle."""
    suns = plan.solar_suns if plan.with_solar else 0.0
    pred = predict_view(spec, base_dir, twin, turntable_deg, solar_suns=suns, seed=seed)
    dark = pred.frame(ambient_scale=0.0)
    slope = sbi = None
    if plan.with_solar:
        base = dark.raw.intensity.astype(np.float64)
        lin = pred.frame(ambient_scale=SOLAR_SCALE_LINEAR).raw.intensity.astype(np.float64)
        slope = (lin - base) / SOLAR_SCALE_LINEAR
        sbi = pred.frame(ambient_scale=SOLAR_SCALE_SBI).raw.intensity.astype(np.float64)
    geometry = plate_geometry(pred.scene, pred.rendered.light_field, plan.edge_margin_px)
    return ReferenceView(float(turntable_deg), plan.reference_albedo,
                         dark.image.amplitude.astype(np.float64),
                         dark.image.range_m.astype(np.float64), slope, sbi, geometry)


def plate_geometry(scene: Scene, light_field, edge_margin_px: int) -> PlateGeometry:
    """The plate's pixels away from its outline and their shading-frame directions.

    ``light_field`` is the render of ``scene`` (its ground-truth range, normals and object ids
    through each pixel's centre).
    """
    if SAMPLE_NAME not in scene.object_names:
        return PlateGeometry(np.zeros(light_field.hit.shape, dtype=bool), np.zeros((0, 3)),
                             np.zeros((0, 3)), None)
    index = scene.object_names.index(SAMPLE_NAME)
    plate = (light_field.object_id == index) & light_field.hit
    mask = ndimage.binary_erosion(plate, iterations=int(edge_margin_px))
    v, u = np.nonzero(mask)
    cam = scene.camera.position_m
    rays = scene.camera.pixel_directions_world(u.astype(np.float64), v.astype(np.float64))
    points = cam + rays * light_field.truth_range_m[v, u][:, None]
    normals = light_field.truth_normal[v, u]
    t, b = frame_from_normal(normals)

    def local(w: np.ndarray) -> np.ndarray:
        w = w / np.linalg.norm(w, axis=1, keepdims=True)
        return to_local(w, t, b, normals)

    sun = next((a for a in scene.ambient if a.name == "solar_simulator"), None)
    to_sun = None
    if sun is not None:
        to_sun = local(np.broadcast_to(-np.asarray(sun.direction, dtype=np.float64),
                                       points.shape).copy())
    return PlateGeometry(mask, local(scene.light.position_m - points), local(cam - points),
                         to_sun)
