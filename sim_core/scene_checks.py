"""Checks of a posed scene that need ray casting."""

from __future__ import annotations

import numpy as np

from sim_core.errors import SceneError
from sim_core.scene import Scene
from sim_core.tracing import RayTracer

#: directions probed from the camera centre
N_PROBES = 64
#: fraction of probes that must see a back face first for the camera to count as enclosed
ENCLOSED_FRACTION = 0.95


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform unit directions, (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def assert_camera_outside_closed_meshes(scene: Scene, tracer: RayTracer) -> None:
    """Raise :class:`SceneError` if the camera sits inside a closed mesh.

    Casts rays in all directions from the camera centre: inside a closed mesh with outward
    normals, every ray meets a back face first.
    """
    if scene.n_triangles == 0:
        return
    d = fibonacci_sphere(N_PROBES)
    _, prim = tracer.intersect(np.zeros_like(d), d)
    if np.any(prim < 0):
        return
    back = np.einsum("ij,ij->i", scene.normals[prim], d) > 0.0
    if back.mean() < ENCLOSED_FRACTION:
        return
    objects = scene.object_index[prim[back]]
    name = scene.object_names[int(np.bincount(objects).argmax())]
    pos = np.round(scene.camera.position_m, 6).tolist()
    raise SceneError(
        "camera.pose.position_m",
        f"the camera at {pos} m is inside the closed mesh of object '{name}'; "
        "it must be outside every closed mesh",
    )
