"""The mount's 6-DoF pose offset by point-to-plane ICP against its meshes (issue 14, section 3).

Every view's points go to the mount frame (:mod:`calibration.object_twin.views`) and are merged;
the target is the on-turntable objects' meshes at their nominal pose, densely sampled with their
face normals (faces turned away from the camera in every view are left out: they were never
seen, and a thin panel's back face would otherwise attract the points of its front face).
Open3D's point-to-plane ICP with a Tukey kernel (robust to the mixed pixels and multipath the
edge filter leaves) registers the measured points to the model, from the nominal pose, at
shrinking correspondence distances. Its transform ``T`` maps the measured (real) object onto the
nominal one, so the mount offset is ``M = T^-1``, expressed in the reality's convention
(:class:`sim_core.twin_file.MountParameters`: ``x' = c + R (x - c) + t`` about the nominal axis
point ``c``, extrinsic xyz Euler angles): :func:`offset_from_transform`.

Checks, so that no wrong pose is ever reported: enough measured points near the model at the
nominal pose (else the cloud does not overlap the mesh: wrong object, wrong place, wrong scene),
and after ICP a large share of them matched within a few millimetres.

ICP on this object determines the horizontal position and the rotations well, the height less
well: every face the camera sees is vertical, so only the silhouette's top and bottom edges say
where the object is along the axis (:mod:`calibration.object_twin.refine` settles it on the
rendered phasors).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from sim_core.errors import InvalidInputError
from sim_core.geometry import rotation_matrix_xyz_deg, triangle_areas
from sim_core.scene import build_scene
from sim_core.scene_spec import ObjectPose, SceneSpec
from sim_core.tracing import RayTracer
from sim_core.twin_file import TwinParameters

#: spacing of the model's surface samples [m]
SAMPLE_SPACING_M = 0.0015
#: a sample counts as seen if the first hit from the camera is at most this in front of it [m]
VISIBLE_TOLERANCE_M = 1e-4
#: measured points farther than this from the nominal model are not the object's [m]
#: (mount offsets up to 10 mm and 2 deg at 0.15 m from the axis move a surface ~16 mm)
CROP_M = 0.025
#: ICP's correspondence distances, coarse to fine [m]
ICP_DISTANCES_M = (0.02, 0.01, 0.006)
#: Tukey kernel's width [m] (a few times the averaged range noise)
TUKEY_K_M = 0.008
#: least number of measured points near the model
MIN_POINTS = 150
#: least share of the points near the model that ICP matches within its finest distance
MIN_FITNESS = 0.5


@dataclass(frozen=True)
class MountModel:
    """The mounted objects at their nominal pose, turntable at zero (world frame).

    Attributes
    ----------
    triangles_m : (n, 3, 3) float64
    normals : (n, 3) float64
    object_index : (n,) int
        Index into ``names``.
    names : tuple of str
        The on-turntable objects.
    axis_point_m : (3,) float64
        The nominal axis point ``c`` the offset turns about.
    """

    triangles_m: np.ndarray = field(repr=False)
    normals: np.ndarray = field(repr=False)
    object_index: np.ndarray = field(repr=False)
    names: tuple[str, ...]
    axis_point_m: np.ndarray = field(repr=False)


def mount_model(spec: SceneSpec, base_dir: str | Path) -> MountModel:
    """The on-turntable objects of ``spec`` at their nominal pose, turntable at zero.

    Raises
    ------
    InvalidInputError
        No turntable, or nothing on it.
    """
    if spec.turntable is None:
        raise InvalidInputError("spec.turntable", "the scene has no turntable: no mount to fit")
    mounted = [o for o in spec.objects if o.on_turntable]
    if not mounted:
        raise InvalidInputError("spec.objects", "no object is on the turntable: nothing to fit")
    only = spec.model_copy(update={"objects": mounted, "calibration": None, "object_twin": None})
    scene = build_scene(only, base_dir, turntable_deg=0.0, twin=TwinParameters())
    return MountModel(scene.triangles_m, scene.normals, scene.object_index, scene.object_names,
                      np.asarray(spec.turntable.axis_point_m, dtype=np.float64))


def sample_model(model: MountModel, camera_positions_m: np.ndarray,
                 spacing_m: float = SAMPLE_SPACING_M, seed: int = 0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, normals and object indices sampled where some view's camera sees the model.

    Area-uniform random samples, about one per ``spacing_m`` squared, on the faces that face
    some camera; a sample is kept if, from one of the cameras, nothing of the model lies in
    front of it (Embree ray casts: a hidden face, such as the pedestal's top under the body,
    would otherwise attract the points of the faces in front of it).
    """
    tris, normals = model.triangles_m, model.normals
    centroids = tris.mean(axis=1)
    cams = np.asarray(camera_positions_m, dtype=np.float64).reshape(-1, 3)
    facing = np.zeros(len(tris), dtype=bool)
    for cam in cams:
        facing |= np.einsum("ij,ij->i", normals, cam - centroids) > 0.0
    areas = triangle_areas(tris) * facing
    n = max(1, int(np.ceil(areas.sum() / spacing_m**2)))
    rng = np.random.default_rng(seed)
    face = rng.choice(len(tris), size=n, p=areas / areas.sum())
    a, b = rng.random(n), rng.random(n)
    flip = a + b > 1.0
    a[flip], b[flip] = 1.0 - a[flip], 1.0 - b[flip]
    t = tris[face]
    pts = t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])
    seen = np.zeros(n, dtype=bool)
    for cam in cams:
        with RayTracer(tris, cam, threads=1) as tracer:
            d = pts - cam
            dist = np.linalg.norm(d, axis=1)
            t_hit, _ = tracer.intersect(np.zeros_like(d), d / dist[:, None])
        seen |= (t_hit >= dist - VISIBLE_TOLERANCE_M) & (
            np.einsum("ij,ij->i", normals[face], cam - pts) > 0.0)
    return pts[seen], normals[face][seen], model.object_index[face][seen]


def transform_from_offset(offset: ObjectPose, axis_point_m) -> np.ndarray:
    """4x4 of the mount offset ``x' = c + R (x - c) + t`` (the reality's convention)."""
    r = rotation_matrix_xyz_deg(offset.rotation_deg)
    c = np.asarray(axis_point_m, dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = c - r @ c + np.asarray(offset.position_m, dtype=np.float64)
    return m


def offset_from_transform(m: np.ndarray, axis_point_m) -> ObjectPose:
    """The mount offset (reality's convention) of a rigid 4x4 ``m``: inverse of
    :func:`transform_from_offset`."""
    r = np.asarray(m, dtype=np.float64)[:3, :3]
    c = np.asarray(axis_point_m, dtype=np.float64)
    t = np.asarray(m, dtype=np.float64)[:3, 3] - c + r @ c
    angles = Rotation.from_matrix(r).as_euler("xyz", degrees=True)
    return ObjectPose(position_m=tuple(float(v) for v in t),
                      rotation_deg=tuple(float(v) for v in angles))


@dataclass(frozen=True)
class Registration:
    """ICP's result.

    Attributes
    ----------
    offset : ObjectPose
        The mount's pose offset (reality's convention).
    transform : (4, 4) float64
        The offset as a matrix (nominal -> real, mount frame).
    fitness : float
        Share of the points near the model matched within the finest distance.
    inlier_rmse_m : float
        RMS point-to-plane distance of the matched points [m].
    n_points : int
        Measured points near the model (used).
    n_points_total : int
        All measured points.
    std : dict
        Standard deviations from Open3D's information matrix scaled by the residual variance:
        ``rotation_deg`` (about x, y, z) and ``translation_m``.
    """

    offset: ObjectPose
    transform: np.ndarray = field(repr=False)
    fitness: float
    inlier_rmse_m: float
    n_points: int
    n_points_total: int
    std: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"offset": self.offset.model_dump(mode="json"), "fitness": self.fitness,
                "inlier_rmse_mm": self.inlier_rmse_m * 1e3, "points_used": self.n_points,
                "points_total": self.n_points_total, "std": self.std}


def _cloud(points: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals))
    return pc


def register_mount(
    points_mount_m: np.ndarray,
    model: MountModel,
    camera_positions_m: np.ndarray,
    crop_m: float = CROP_M,
    distances_m: tuple[float, ...] = ICP_DISTANCES_M,
    tukey_k_m: float = TUKEY_K_M,
    min_points: int = MIN_POINTS,
    min_fitness: float = MIN_FITNESS,
    seed: int = 0,
) -> Registration:
    """Register the merged measured points (mount frame) to the model (module docstring).

    Raises
    ------
    InvalidInputError
        ``mesh``: the points do not overlap the model (too few near it at the nominal pose, or
        too few matched after ICP); never a pose in that case.
    """
    pts = np.asarray(points_mount_m, dtype=np.float64).reshape(-1, 3)
    target_pts, target_normals, _ = sample_model(model, camera_positions_m, seed=seed)
    near_dist, _ = cKDTree(target_pts).query(pts, distance_upper_bound=crop_m)
    near = np.isfinite(near_dist)
    n_near = int(near.sum())
    if n_near < min_points:
        raise InvalidInputError(
            "mesh", f"the measured point cloud does not overlap the mounted objects' meshes "
            f"{list(model.names)}: {n_near} of {len(pts)} points lie within "
            f"{crop_m * 1e3:.0f} mm of them at the nominal pose, at least {min_points} are "
            "needed (is the right object mounted, where the scene says?)")
    source = _cloud(pts[near])
    target = _cloud(target_pts, target_normals)
    reg = o3d.pipelines.registration
    estimation = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=tukey_k_m))
    t = np.eye(4)
    result = None
    for d in distances_m:
        result = reg.registration_icp(source, target, d, t, estimation,
                                      reg.ICPConvergenceCriteria(1e-9, 1e-9, 60))
        t = np.asarray(result.transformation)
    fitness = float(result.fitness)
    if fitness < min_fitness:
        raise InvalidInputError(
            "mesh", f"the measured point cloud does not fit the mounted objects' meshes "
            f"{list(model.names)}: after ICP only {fitness:.0%} of the {n_near} points near them "
            f"lie within {distances_m[-1] * 1e3:.0f} mm (at least {min_fitness:.0%} needed); no "
            "pose is reported")
    info = np.asarray(reg.get_information_matrix_from_point_clouds(
        source, target, distances_m[-1], t))
    rmse = float(result.inlier_rmse)
    std: dict = {}
    try:
        cov = rmse**2 * np.linalg.inv(info)
        d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        std = {"rotation_deg": np.degrees(d[:3]).tolist(), "translation_m": d[3:].tolist()}
    except np.linalg.LinAlgError:
        std = {"singular": True}
    m = np.linalg.inv(t)
    return Registration(offset_from_transform(m, model.axis_point_m), m, fitness, rmse, n_near,
                        len(pts), std)
