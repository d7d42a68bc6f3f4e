"""Our scene as a Mitsuba 3 scene, for ``toftwin bench mitsuba``: the same triangles, camera,
light, material and path integrator, so that the two renderers' images can be compared.

What is matched
---------------
- geometry: ``scene.triangles_m`` as one triangle mesh per material (written to a temporary
  binary PLY and loaded with face normals), so both trace the same float32 triangles;
- camera: ``perspective`` sensor with ``to_world`` = our ``world_from_camera`` with x and y
  negated (Mitsuba's camera frame is x left, y up; ours x right, y down), horizontal field of
  view ``2 atan(W / (2 fx))`` on ``fov_axis = x``, principal point offset from ``cx, cy`` (0 for a
  centred one), the same resolution; checked by comparing Mitsuba's primary ray directions to
  ours at pixel centres and corners. Mitsuba has square pixels and no lens distortion, so
  ``fx != fy`` or distortion are refused;
- pixel filter: Mitsuba's ``box`` reconstruction filter (radius 0.5 px, a sample only counts in
  its own pixel) with the ``independent`` sampler = our uniform jitter over the pixel footprint;
- light: ``point`` emitter at the light position with intensity ``P / (4 pi)`` W/sr;
- material: ``twosided`` ``diffuse`` with the object's albedo (ours is two-sided Lambertian);
- integrator: ``path`` with ``max_depth = bounces + 1`` (Mitsuba counts the camera vertex) and
  ``rr_depth = russian_roulette_from_bounce - 1``: both then apply Russian roulette at the same
  vertices with the same survival probability for this scene (min(throughput, 0.95) vs.
  min(1, max(0.05, throughput))), i.e. with the default (5) only when continuing to a fifth
  bounce: never within the benchmark's 1-3 bounces.

What differs
------------
- ours also computes the modulation phasor (path lengths) and per-pixel variances, and traces
  one extra primary ray per pixel for the ground-truth images; Mitsuba computes radiance only;
- ours does float64 shading arithmetic on float32 rays; Mitsuba is float32 throughout;
- Mitsuba starts camera rays at its near clip plane (0.01 m; the walls are > 1 m away).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sim_core.materials.lambertian import Lambertian
from sim_core.scene import Scene


def write_ply(path: Path, triangles: np.ndarray) -> None:
    """Binary little-endian PLY of unshared float32 triangles ``(n, 3, 3)``."""
    tris = np.asarray(triangles, dtype="<f4").reshape(-1, 3)
    n = tris.shape[0] // 3
    faces = np.empty(n, dtype=[("k", "u1"), ("i", "<i4", (3,))])
    faces["k"] = 3
    faces["i"] = np.arange(3 * n, dtype="<i4").reshape(n, 3)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {3 * n}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {n}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(tris.tobytes())
        fh.write(faces.tobytes())


def mitsuba_sensor_dict(mi, scene: Scene, spp: int = 16) -> dict:
    """Perspective sensor matching our pinhole camera (see the module docstring)."""
    intr = scene.camera.intrinsics
    if intr.has_distortion:
        raise ValueError("Mitsuba's perspective sensor has no lens distortion; use k = 0")
    if not math.isclose(intr.fx_px, intr.fy_px, rel_tol=1e-9):
        raise ValueError(
            f"Mitsuba's perspective sensor has square pixels; fx = {intr.fx_px} != "
            f"fy = {intr.fy_px}"
        )
    w, h = intr.width_px, intr.height_px
    # Mitsuba's camera frame: x left, y up, z forward; ours: x right, y down, z forward.
    to_world = scene.camera.world_from_camera @ np.diag([-1.0, -1.0, 1.0, 1.0])
    return {
        "type": "perspective",
        "fov": float(2.0 * np.degrees(np.arctan(0.5 * w / intr.fx_px))),
        "fov_axis": "x",
        # film position (u + 0.5) / W of our pixel u; Mitsuba adds the offset to it
        "principal_point_offset_x": float(0.5 - (intr.cx_px + 0.5) / w),
        "principal_point_offset_y": float(0.5 - (intr.cy_px + 0.5) / h),
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {
            "type": "hdrfilm",
            "width": w,
            "height": h,
            "pixel_format": "luminance",
            "component_format": "float32",
            "rfilter": {"type": "box"},
        },
    }


def mitsuba_scene_dict(mi, scene: Scene, workdir: Path) -> dict:
    """Mitsuba scene dictionary of ``scene`` (Lambertian materials, isotropic light only).

    The meshes are written as PLY files into ``workdir``, which must exist until the
    dictionary has been loaded.
    """
    light = scene.light
    if light.profile_angle_rad is not None:
        raise ValueError("only an isotropic point source is translated to Mitsuba")
    d: dict = {
        "type": "scene",
        "sensor": mitsuba_sensor_dict(mi, scene),
        "light": {
            "type": "point",
            "position": [float(x) for x in light.position_m],
            "intensity": float(light.power_w / (4.0 * np.pi)),
        },
    }
    for m_idx, material in enumerate(scene.materials):
        sel = scene.material_index == m_idx
        if not sel.any():
            continue
        if not isinstance(material, Lambertian):
            raise ValueError(
                f"material {m_idx} is {type(material).__name__}; only Lambertian is translated"
            )
        path = Path(workdir) / f"material_{m_idx}.ply"
        write_ply(path, scene.triangles_m[sel])
        d[f"mesh_{m_idx}"] = {
            "type": "ply",
            "filename": str(path),
            "face_normals": True,
            "bsdf": {
                "type": "twosided",
                "material": {"type": "diffuse", "reflectance": float(material.albedo)},
            },
        }
    return d


def mitsuba_integrator(mi, bounces: int, rr_from_bounce: int):
    """Mitsuba ``path`` integrator equivalent to our ``bounces`` and Russian roulette start."""
    return mi.load_dict(
        {
            "type": "path",
            "max_depth": int(bounces) + 1,
            "rr_depth": max(1, int(rr_from_bounce) - 1),
        }
    )


def camera_mismatch_deg(mi, mscene, scene: Scene) -> float:
    """Largest angle between Mitsuba's and our primary rays at pixel centres and corners [deg]."""
    intr = scene.camera.intrinsics
    w, h = intr.width_px, intr.height_px
    us = np.array([-0.5, 0.0, w / 2 - 0.5, w - 1.0, w - 0.5])
    vs = np.array([-0.5, 0.0, h / 2 - 0.5, h - 1.0, h - 0.5])
    u, v = (a.ravel() for a in np.meshgrid(us, vs))
    sensor = mscene.sensors()[0]
    pos = mi.Point2f(((u + 0.5) / w).astype(np.float32), ((v + 0.5) / h).astype(np.float32))
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    dm = np.asarray(ray.d, dtype=np.float64)
    if dm.shape[0] == 3 and dm.shape[1] != 3:
        dm = dm.T
    do = scene.camera.pixel_directions_world(u, v)
    # atan2 of |cross| and dot: accurate for tiny angles, unlike arccos of the dot
    ang = np.arctan2(np.linalg.norm(np.cross(dm, do), axis=1), np.einsum("ij,ij->i", dm, do))
    return float(np.degrees(ang.max()))
