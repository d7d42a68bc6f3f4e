"""The mount's 6-DoF pose offset by point-to-plane ICP against its meshes (issue 14, section 3).

Every view's points go to the mount frame (:mod:`calibration.object_twin.views`) and are merged;
the target is the on-turntable objects' meshes at their nominal pose, densely sampled with their
face normals (faces turned away from the camera in every view are left out: they were never
seen, and a thin panel's back face would otherwise attract the points of its front face).
Point-to-plane ICP with a Tukey kernel (robust to the mixed pixels and multipath the edge
filter leaves) registers the measured points to the model, from the nominal pose, at shrinking
correspondence distances (:func:`icp_point_to_plane`: scipy's KD-tree for the nearest model
sample, one Gauss-Newton step of the Tukey-weighted point-to-plane residuals per correspondence
search). Its transform ``T`` maps the measured (real) object onto the nominal one, so the mount
offset is ``M = T^-1``, expressed in the reality's convention
(:class:`sim_core.twin_file.MountParameters`: ``x' = c + R (x - c) + t`` about the nominal axis
point ``c``, extrinsic xyz Euler angles): :func:`offset_from_transform`. Single-threaded and
free of order effects: the same points give the same pose to the last bit.

Checks, so that no wrong pose is ever reported: enough measured points near the model at the
nominal pose (else the cloud does not overlap the mesh: wrong object, wrong place, wrong scene),
and after ICP a large share of them matched within a few millimetres.

ICP on this object determines the horizontal position and the rotations, not the height: every
face the camera sees from the side is vertical, and a vertical face's point-to-plane residuals
are horizontal, so ICP takes no step along the axis and reports that component's standard
deviation as infinite (only the silhouette's top and bottom edges say where the object is along
the axis: :mod:`calibration.object_twin.refine` settles it on the rendered phasors).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
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
#: ICP stops at a distance when fitness and inlier RMSE [m] change less than these between two
#: iterations, or after this many iterations
ICP_RELATIVE_FITNESS, ICP_RELATIVE_RMSE_M, ICP_MAX_ITERATIONS = 1e-9, 1e-9, 60
#: eigenvalues of J^T J at most this times the largest are directions the points do not
#: determine: ICP takes no step along them, their standard deviation is infinite
RCOND = 1e-9
#: a pose component is undetermined if this much of it lies along such directions
NULL_SHARE = 1e-6
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
        Standard deviations of the ICP pose, ``rotation_deg`` (about the mount frame's x, y, z
        axes through its origin) and ``translation_m``: the inverse of the information matrix
        (:func:`information_matrix`) times the squared inlier RMSE (:func:`pose_std`);
        infinite along what the matched faces do not determine (the height, when all of them
        are vertical: the report shows it as null).
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


@dataclass(frozen=True)
class IcpResult:
    """One ICP run's result (:func:`icp_point_to_plane`).

    Attributes
    ----------
    transform : (4, 4) float64
        Maps the source points onto the target.
    fitness : float
        Share of the source points with a target sample within the correspondence distance.
    inlier_rmse_m : float
        RMS point-to-plane distance of those correspondences [m].
    iterations : int
        Gauss-Newton steps taken.
    """

    transform: np.ndarray = field(repr=False)
    fitness: float
    inlier_rmse_m: float
    iterations: int


def _correspond(tree: cKDTree, target_normals: np.ndarray, moved: np.ndarray, distance_m: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source indices with a target sample within ``distance_m``, their samples' indices and
    point-to-plane residuals ``(p - q) . n``."""
    dist, idx = tree.query(moved, distance_upper_bound=distance_m, workers=1)
    src = np.flatnonzero(np.isfinite(dist))
    tgt = idx[src]
    r = np.einsum("ij,ij->i", moved[src] - tree.data[tgt], target_normals[tgt])
    return src, tgt, r


def _fitness_rmse(n_source: int, r: np.ndarray) -> tuple[float, float]:
    if r.size == 0:
        return 0.0, 0.0
    return r.size / n_source, float(np.sqrt(np.einsum("i,i->", r, r) / r.size))


def _eigen(a: np.ndarray, rcond: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues and vectors of a symmetric PSD 6x6, and which are determined (above
    ``rcond`` times the largest)."""
    lam, vec = np.linalg.eigh(a)
    top = float(lam[-1])
    return lam, vec, (lam > rcond * top) if top > 0.0 else np.zeros(lam.shape, dtype=bool)


def _solve_psd(a: np.ndarray, b: np.ndarray, rcond: float = RCOND) -> np.ndarray:
    """The least-norm ``x`` of ``a x = b`` for a symmetric PSD ``a``: no step along directions
    the residuals do not determine (eigenvalues at most ``rcond`` times the largest; e.g. the
    height, when every matched face is vertical)."""
    lam, vec, keep = _eigen(a, rcond)
    v = vec[:, keep]
    return v @ ((v.T @ b) / lam[keep])


def pose_std(info: np.ndarray, rmse_m: float, rcond: float = RCOND) -> dict[str, list[float]]:
    """Standard deviations of a pose from its information matrix (:func:`information_matrix`)
    and residual RMS: ``rmse_m^2 info^-1``'s diagonal, square-rooted; ``rotation_deg`` (about
    x, y, z through the origin) and ``translation_m``. A component along a direction the
    matrix does not determine is infinite."""
    lam, vec, keep = _eigen(info, rcond)
    var = (vec[:, keep] ** 2 / lam[keep]).sum(axis=1) * rmse_m**2
    var[(vec[:, ~keep] ** 2).sum(axis=1) > NULL_SHARE] = np.inf
    d = np.sqrt(var)
    return {"rotation_deg": np.degrees(d[:3]).tolist(), "translation_m": d[3:].tolist()}


def _jacobian(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """d residual / d (small rotation about the origin, translation): rows ``[p x n, n]``."""
    return np.hstack([np.cross(points, normals), normals])


def icp_point_to_plane(
    source_m: np.ndarray,
    target_m: np.ndarray,
    target_normals: np.ndarray,
    distances_m: tuple[float, ...] = ICP_DISTANCES_M,
    tukey_k_m: float = TUKEY_K_M,
    init: np.ndarray | None = None,
    relative_fitness: float = ICP_RELATIVE_FITNESS,
    relative_rmse_m: float = ICP_RELATIVE_RMSE_M,
    max_iterations: int = ICP_MAX_ITERATIONS,
) -> IcpResult:
    """Point-to-plane ICP with a Tukey kernel, coarse to fine: ``source`` onto ``target``.

    At each correspondence distance in turn: every source point (moved by the current
    transform) is paired with its nearest target sample if that lies within the distance; one
    Gauss-Newton step on the point-to-plane residuals ``r = (p - q) . n``, each weighted by
    Tukey's ``(1 - (r / k)^2)^2`` (0 beyond ``k``), linearised in a small rotation about the
    origin and a translation, gives an update that is made an exact rotation
    (:meth:`scipy.spatial.transform.Rotation.from_rotvec`) and composed on the left; repeated
    until fitness and inlier RMSE change less than ``relative_fitness`` and
    ``relative_rmse_m`` (or ``max_iterations`` steps). Fitness and RMSE are those of the finest
    distance's last correspondences.

    Examples
    --------
    Three faces of a box corner recover a small shift:

    >>> g = np.linspace(0.0, 0.1, 21)
    >>> u, v = (a.ravel() for a in np.meshgrid(g, g))
    >>> o = np.zeros_like(u)
    >>> target = np.r_[np.c_[u, v, o], np.c_[u, o, v], np.c_[o, u, v]]
    >>> normals = np.repeat([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], u.size, axis=0)
    >>> res = icp_point_to_plane(target + (0.002, -0.001, 0.001), target, normals)
    >>> np.round(res.transform[:3, 3] * 1e3, 6).tolist(), res.fitness
    ([-2.0, 1.0, -1.0], 1.0)
    """
    src = np.asarray(source_m, dtype=np.float64).reshape(-1, 3)
    tgt_normals = np.asarray(target_normals, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(np.asarray(target_m, dtype=np.float64).reshape(-1, 3))
    t = np.eye(4) if init is None else np.array(init, dtype=np.float64)
    fitness, rmse, steps = 0.0, 0.0, 0
    for distance in distances_m:
        moved = src @ t[:3, :3].T + t[:3, 3]
        idx, tidx, r = _correspond(tree, tgt_normals, moved, distance)
        fitness, rmse = _fitness_rmse(len(src), r)
        for _ in range(max_iterations):
            w = np.clip(1.0 - (r / tukey_k_m) ** 2, 0.0, None) ** 2
            if np.count_nonzero(w) < 6:
                break
            jac = _jacobian(moved[idx], tgt_normals[tidx])
            jtj = np.einsum("ni,n,nj->ij", jac, w, jac)
            jtr = np.einsum("ni,n->i", jac, w * r)
            x = -_solve_psd(jtj, jtr)
            update = np.eye(4)
            update[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
            update[:3, 3] = x[3:]
            t = update @ t
            t[:3, :3] = Rotation.from_matrix(t[:3, :3]).as_matrix()  # re-orthonormalised
            steps += 1
            moved = src @ t[:3, :3].T + t[:3, 3]
            idx, tidx, r = _correspond(tree, tgt_normals, moved, distance)
            previous = fitness, rmse
            fitness, rmse = _fitness_rmse(len(src), r)
            if (abs(fitness - previous[0]) < relative_fitness
                    and abs(rmse - previous[1]) < relative_rmse_m):
                break
    return IcpResult(t, fitness, rmse, steps)


def information_matrix(source_m: np.ndarray, target_m: np.ndarray, target_normals: np.ndarray,
                       distance_m: float, transform: np.ndarray) -> np.ndarray:
    """6x6 ``J^T J`` of the point-to-plane residuals over the correspondences within
    ``distance_m`` at ``transform``: rows of ``J`` are ``[p x n, n]`` (a small rotation about the
    origin, then a translation), unweighted. Its inverse times the residual variance is the
    pose's covariance."""
    src = np.asarray(source_m, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(transform, dtype=np.float64)
    moved = src @ t[:3, :3].T + t[:3, 3]
    normals = np.asarray(target_normals, dtype=np.float64).reshape(-1, 3)
    idx, tidx, _ = _correspond(cKDTree(np.asarray(target_m, dtype=np.float64).reshape(-1, 3)),
                               normals, moved, distance_m)
    jac = _jacobian(moved[idx], normals[tidx])
    return np.einsum("ni,nj->ij", jac, jac)


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
    source = pts[near]
    result = icp_point_to_plane(source, target_pts, target_normals, distances_m, tukey_k_m)
    t, fitness, rmse = result.transform, result.fitness, result.inlier_rmse_m
    if fitness < min_fitness:
        raise InvalidInputError(
            "mesh", f"the measured point cloud does not fit the mounted objects' meshes "
            f"{list(model.names)}: after ICP only {fitness:.0%} of the {n_near} points near them "
            f"lie within {distances_m[-1] * 1e3:.0f} mm (at least {min_fitness:.0%} needed); no "
            "pose is reported")
    info = information_matrix(source, target_pts, target_normals, distances_m[-1], t)
    std = pose_std(info, rmse)
    m = np.linalg.inv(t)
    return Registration(offset_from_transform(m, model.axis_point_m), m, fitness, rmse, n_near,
                        len(pts), std)
