"""Triangle meshes: primitives, files, rigid transforms, validation.

Meshes are plain arrays ``triangles : (n, 3, 3) float64`` in metres (triangle, corner, xyz).
Normals follow the right-hand rule of the corner order; surfaces are shaded two-sided, so the
winding only matters for the "camera inside a closed mesh" check.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim_core.errors import SceneError

#: triangles whose area is below this are "degenerate" (no well-defined normal) [m^2]
DEGENERATE_AREA_M2 = 1e-24


def box_triangles(size_m) -> np.ndarray:
    """Closed box centred at the origin with outward normals; ``size_m`` = (sx, sy, sz)."""
    sx, sy, sz = (0.5 * float(s) for s in size_m)
    c = np.array(
        [[-sx, -sy, -sz], [sx, -sy, -sz], [sx, sy, -sz], [-sx, sy, -sz],
         [-sx, -sy, sz], [sx, -sy, sz], [sx, sy, sz], [-sx, sy, sz]]
    )
    quads = [
        (0, 3, 2, 1),  # -z
        (4, 5, 6, 7),  # +z
        (0, 1, 5, 4),  # -y
        (2, 3, 7, 6),  # +y
        (1, 2, 6, 5),  # +x
        (0, 4, 7, 3),  # -x
    ]
    tris = []
    for a, b, cc, d in quads:
        tris.append([c[a], c[b], c[cc]])
        tris.append([c[a], c[cc], c[d]])
    return np.asarray(tris, dtype=np.float64)


def rectangle_triangles(size_m) -> np.ndarray:
    """Rectangle in the object's z = 0 plane, centred at the origin, normal +z.

    ``size_m`` = (sx, sy) along x and y.
    """
    sx, sy = (0.5 * float(s) for s in size_m)
    p = np.array([[-sx, -sy, 0.0], [sx, -sy, 0.0], [sx, sy, 0.0], [-sx, sy, 0.0]])
    return np.asarray([[p[0], p[1], p[2]], [p[0], p[2], p[3]]], dtype=np.float64)


def sphere_triangles(radius_m: float, subdivisions: int = 4) -> np.ndarray:
    """Icosphere of ``radius_m`` centred at the origin, outward normals.

    The chord error (largest distance between a facet and the true sphere) is about
    ``radius_m * (1 - cos(edge_angle / sqrt(3)))``; see :func:`icosphere_max_chord_error_m`.
    """
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=float(radius_m))
    return np.asarray(mesh.triangles, dtype=np.float64)


def icosphere_max_chord_error_m(radius_m: float, subdivisions: int) -> float:
    """Upper bound of the distance between an icosphere's facets and its sphere [m]."""
    tris = sphere_triangles(radius_m, subdivisions)
    centroids = tris.mean(axis=1)
    return float(radius_m - np.linalg.norm(centroids, axis=1).min())


def load_mesh_file(path: Path, field: str) -> np.ndarray:
    """Triangles of a mesh file (OBJ, STL, PLY, GLB, ...) via trimesh, in the file's units.

    Raises
    ------
    SceneError
        If the file is missing, unreadable or holds no triangles.
    """
    import trimesh

    if not path.is_file():
        raise SceneError(field, f"mesh file '{path}' does not exist")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a malformed file
        raise SceneError(field, f"mesh file '{path}' could not be read: {exc}") from exc
    tris = np.asarray(getattr(loaded, "triangles", np.empty((0, 3, 3))), dtype=np.float64)
    return tris.reshape(-1, 3, 3)


def validate_triangles(tris: np.ndarray, field: str) -> np.ndarray:
    """Check a triangle array and drop degenerate triangles.

    Returns the triangles with zero-area ones removed (they have no normal and Embree never
    reports hits on them). Raises :class:`SceneError` for an empty mesh, non-finite
    coordinates, or a mesh with only degenerate triangles.
    """
    tris = np.asarray(tris, dtype=np.float64)
    if tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise SceneError(field, f"triangles must have shape (n, 3, 3), got {tris.shape}")
    if tris.shape[0] == 0:
        raise SceneError(field, "the mesh is empty (0 triangles); it needs at least 1")
    bad = ~np.isfinite(tris).all(axis=(1, 2))
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise SceneError(
            field,
            f"{int(bad.sum())} triangle(s) have NaN or infinite vertex coordinates "
            f"(first: triangle {first}); every coordinate must be a finite number of metres",
        )
    area = triangle_areas(tris)
    keep = area > DEGENERATE_AREA_M2
    if not keep.any():
        raise SceneError(field, "every triangle of the mesh is degenerate (zero area)")
    return tris[keep]


def triangle_areas(tris: np.ndarray) -> np.ndarray:
    """Areas of ``(n, 3, 3)`` triangles [m^2]."""
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return 0.5 * np.linalg.norm(cross, axis=1)


def face_normals(tris: np.ndarray) -> np.ndarray:
    """Unit normals of ``(n, 3, 3)`` triangles, right-hand rule; (n, 3) float64.

    Degenerate triangles (which :func:`validate_triangles` removes) would get (0, 0, 1).
    """
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    norm = np.linalg.norm(cross, axis=1, keepdims=True)
    out = np.zeros_like(cross)
    out[:, 2] = 1.0
    # Dividing by a zero norm would give NaN normals for degenerate triangles.
    ok = norm[:, 0] > 0.0
    out[ok] = cross[ok] / norm[ok]
    return out


# The two rotations a scene is posed with are written out here rather than taken from scipy's
# ``Rotation`` (which the rest of the project uses for every conversion back, matrix to angles
# or rotation vector): they are the scene format's definition, and a frame must not change with
# the scipy release a lab installs. scipy goes through quaternions and lands within a few
# 1e-16 of these, not on them, so a frame would differ in its last bits between the two.
# tests/sim_core/test_geometry.py holds them to scipy's ``from_euler("xyz")`` and
# ``from_rotvec`` on random angles and axes.


def rotation_matrix_xyz_deg(angles_deg) -> np.ndarray:
    """Rotation from extrinsic x, then y, then z rotations [deg] (R = Rz @ Ry @ Rx; scipy's
    ``Rotation.from_euler("xyz", angles_deg, degrees=True)``)."""
    ax, ay, az = np.radians(np.asarray(angles_deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def axis_angle_matrix(axis, angle_rad: float) -> np.ndarray:
    """Rotation by ``angle_rad`` about ``axis`` (Rodrigues), 3x3 (scipy's
    ``Rotation.from_rotvec(axis / |axis| * angle_rad)``)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * kx + (1.0 - np.cos(angle_rad)) * (kx @ kx)


def transform_triangles(tris: np.ndarray, matrix4: np.ndarray) -> np.ndarray:
    """Apply a 4x4 affine transform to ``(n, 3, 3)`` triangles."""
    flat = tris.reshape(-1, 3)
    out = flat @ matrix4[:3, :3].T + matrix4[:3, 3]
    return out.reshape(tris.shape)
