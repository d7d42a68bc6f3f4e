"""The object fit's ICP on random realities of the simulated lab: our point-to-plane ICP
(:func:`calibration.object_twin.pose.register_mount`, scipy's KD-tree) against Open3D's, which
it replaced (issue 24), on the same merged measured points.

For each seed, a reality is drawn as the campaign test draws it
(:func:`tests.calibration.realities.random_reality` with the mounted objects' keys); the simulated
lab's rig captures ``FRAMES`` frames at each of the campaign's fit angles (-60, -30, 0, 30, 60
deg, shutter closed), averaged; the views become points in the mount frame with the reality's
camera and rig keys as the calibration (:func:`calibration.object_twin.fit.measured_points`:
what :func:`calibration.object_twin.fit.fit_object` registers). Both ICPs then register the same
points from the nominal pose, with the same parameters; printed per reality and ICP: the pose
error against the reality's mount offset (position mm, rotation angle deg), fitness, inlier
RMSE, the standard deviations (translation mm, rotation deg) and the seconds.

The Open3D column needs ``pip install open3d-cpu`` (no longer a dependency): without it only
ours is printed. The merged points are cached per seed under ``CACHE`` (a re-run skips the
renders).

Run from the repository root::

    PYTHONPATH=. python docs/plots/icp_realities.py [SEEDS] [FRAMES] [SPP] [CACHE]

defaults ``151-158 32 32 /tmp/icp-realities``; about a minute of renders per reality.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from calibration.captures import average_frames
from calibration.object_twin.fit import measured_points
from calibration.object_twin.pose import (
    CROP_M,
    ICP_DISTANCES_M,
    TUKEY_K_M,
    MountModel,
    Registration,
    mount_model,
    offset_from_transform,
    register_mount,
    sample_model,
)
from drivers.rig import RigState
from drivers.sim.rig import simulated_rig
from drivers.sim.world import SimulatedWorld
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import perfect_calibration, pose_errors, random_reality
from tests.sim_core.scenes import EXAMPLES

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
MOUNTED = [o.name for o in SPEC.objects if o.on_turntable]
ANGLES_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)


def cloud(seed: int, frames: int, spp: int, cache: Path) -> tuple[np.ndarray, np.ndarray]:
    """The merged measured points and the view cameras (mount frame) of reality ``seed``."""
    path = cache / f"reality-{seed}-f{frames}-spp{spp}.npz"
    if path.exists():
        data = np.load(path)
        return data["points"], data["cameras"]
    reality = random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                             object_twin_names=MOUNTED)
    world = SimulatedWorld(SPEC, EXAMPLES, RenderRequest(
        RenderSettings(integrator="path", spp=spp, max_bounces=2), effects="all"), reality=reality)
    captures = []
    with simulated_rig(frame_source=world, seed=seed) as rig, rig.hold():
        for a in ANGLES_DEG:
            rig.apply(RigState(a, 0.0, False))
            captures.append(average_frames(rig.capture(frames)))
    points, cameras, _ = measured_points(SPEC, perfect_calibration(reality), captures)
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, points=points, cameras=cameras)
    return points, cameras


def register_open3d(points: np.ndarray, model: MountModel, cameras: np.ndarray) -> Registration:
    """The object fit's ICP as it was with Open3D (for the comparison only)."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    def pc(p, n=None):
        c = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(p)))
        if n is not None:
            c.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(n))
        return c

    target_pts, target_normals, _ = sample_model(model, cameras, seed=0)
    near_dist, _ = cKDTree(target_pts).query(points, distance_upper_bound=CROP_M)
    near = np.isfinite(near_dist)
    source, target = pc(points[near]), pc(target_pts, target_normals)
    reg = o3d.pipelines.registration
    estimation = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=TUKEY_K_M))
    t = np.eye(4)
    for d in ICP_DISTANCES_M:
        result = reg.registration_icp(source, target, d, t, estimation,
                                      reg.ICPConvergenceCriteria(1e-9, 1e-9, 60))
        t = np.asarray(result.transformation)
    info = np.asarray(reg.get_information_matrix_from_point_clouds(
        source, target, ICP_DISTANCES_M[-1], t))
    rmse = float(result.inlier_rmse)
    d = np.sqrt(np.clip(np.diag(rmse**2 * np.linalg.inv(info)), 0.0, None))
    m = np.linalg.inv(t)
    return Registration(offset_from_transform(m, model.axis_point_m), m, float(result.fitness),
                        rmse, int(near.sum()), len(points),
                        {"rotation_deg": np.degrees(d[:3]).tolist(),
                         "translation_m": d[3:].tolist()})


def _line(name: str, reg: Registration, truth, seconds: float) -> str:
    dp, dr = pose_errors(reg.offset, truth)
    st, sr = reg.std["translation_m"], reg.std["rotation_deg"]
    return (f"  {name:7s} position {dp * 1e3:6.3f} mm  rotation {dr:6.3f} deg  fitness "
            f"{reg.fitness:.4f}  rmse {reg.inlier_rmse_m * 1e3:.3f} mm  std t "
            f"[{', '.join(f'{v * 1e3:.4f}' for v in st)}] mm r "
            f"[{', '.join(f'{v:.4f}' for v in sr)}] deg  {seconds:.2f} s")


def main(argv: list[str]) -> None:
    seeds_arg = argv[0] if argv else "151-158"
    lo, _, hi = seeds_arg.partition("-")
    seeds = range(int(lo), int(hi or lo) + 1)
    frames = int(argv[1]) if len(argv) > 1 else 32
    spp = int(argv[2]) if len(argv) > 2 else 32
    cache = Path(argv[3] if len(argv) > 3 else "/tmp/icp-realities")
    try:
        import open3d  # noqa: F401
        have_o3d = True
    except ImportError:
        have_o3d = False
        print("open3d is not installed: our ICP only")
    model = mount_model(SPEC, EXAMPLES)
    summary: dict[str, list[tuple[float, float]]] = {"ours": [], "open3d": [], "ours - open3d": []}
    for seed in seeds:
        points, cameras = cloud(seed, frames, spp, cache)
        truth = random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                               object_twin_names=MOUNTED).mount.pose_offset
        print(f"reality {seed}: {len(points)} points, offset "
              f"{[round(v * 1e3, 2) for v in truth.position_m]} mm "
              f"{[round(v, 2) for v in truth.rotation_deg]} deg")
        runs = [("ours", register_mount)] + ([("open3d", register_open3d)] if have_o3d else [])
        offsets = {}
        for name, fn in runs:
            t0 = time.perf_counter()
            reg = fn(points, model, cameras)
            seconds = time.perf_counter() - t0
            print(_line(name, reg, truth, seconds))
            summary[name].append(pose_errors(reg.offset, truth))
            offsets[name] = reg.offset
        if len(offsets) == 2:
            dp, dr = pose_errors(offsets["ours"], offsets["open3d"])
            summary["ours - open3d"].append((dp, dr))
            print(f"  ours - open3d: position {dp * 1e3:.3f} mm, rotation {dr:.3f} deg")
    for name, errs in summary.items():
        if errs:
            e = np.array(errs)
            print(f"{name}: median position {np.median(e[:, 0]) * 1e3:.3f} mm (max "
                  f"{e[:, 0].max() * 1e3:.3f}), median rotation {np.median(e[:, 1]):.3f} deg "
                  f"(max {e[:, 1].max():.3f})")


if __name__ == "__main__":
    main(sys.argv[1:])
