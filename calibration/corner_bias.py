"""Removing the corner detector's bias by synthesis: the twin renders what the camera saw.

At this resolution a detected ChArUco corner is off by about 0.1 px, the same way every time
for the same corner seen the same way (the markers' bits next to it, the optics' blur): a bias,
not noise, which averaging frames does not remove and which shifts the principal point. The
twin can measure it: render each view with the first calibration (the board at its fitted pose,
noise-free), detect the corners in the render with the same detector, and compare with where
the calibrated camera projects them. That difference is the detector's bias for the view; the
measured corners minus it are calibrated again.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from calibration.board_detection import detect_board
from calibration.board_views import BoardView
from sim_core.boards import object_from_board
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import Distortion, ObjectSpec, SceneSpec

#: samples per pixel of the synthetic views
SYNTHESIS_SPP = 32


def _board_object_at(board: dict, world_from_board: np.ndarray) -> ObjectSpec:
    world_from_object = world_from_board @ np.linalg.inv(object_from_board(
        ObjectSpec.model_validate({"name": "b", "mesh": board}).mesh))
    angles = Rotation.from_matrix(world_from_object[:3, :3]).as_euler("xyz", degrees=True)
    return ObjectSpec.model_validate({
        "name": "calibration_board", "mesh": board,
        "pose": {"position_m": [float(v) for v in world_from_object[:3, 3]],
                 "rotation_deg": [float(v) for v in angles]}})


def debias_views(views: list[BoardView], intr_result, spec: SceneSpec, base_dir: str | Path,
                 board: dict, world_from_camera: np.ndarray) -> tuple[list[BoardView], float]:
    """The views with each corner's synthetic bias subtracted, and the bias' RMS [px].

    Views without a pose, or whose render shows fewer corners, keep only the corners found in
    both.
    """
    k = intr_result.intrinsics
    kmat = np.array([[k.fx_px, 0, k.cx_px], [0, k.fy_px, k.cy_px], [0, 0, 1.0]])
    dist = np.asarray(k.distortion, dtype=np.float64)
    camera = spec.camera.model_copy(update={
        "fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px,
        "distortion": Distortion(k1=dist[0], k2=dist[1], p1=dist[2], p2=dist[3], k3=dist[4]),
        "width_px": k.width_px, "height_px": k.height_px})
    fixed = [o for o in spec.objects if not o.on_turntable]
    out, biases = [], []
    for v in views:
        pose = intr_result.poses.get(v.name)
        if pose is None:
            continue
        cam_from_board = np.eye(4)
        cam_from_board[:3, :3] = cv2.Rodrigues(pose[0])[0]
        cam_from_board[:3, 3] = pose[1]
        obj = _board_object_at(board, world_from_camera @ cam_from_board)
        synth_spec = spec.model_copy(update={"objects": [*fixed, obj], "camera": camera,
                                             "turntable": None})
        scene = build_scene(synth_spec, base_dir, solar_suns=0.0)
        settings = RenderSettings(integrator="direct", spp=SYNTHESIS_SPP, seed=7)
        frame = simulate(scene, RenderRequest(settings, ideal=True))
        det = detect_board(frame.image.amplitude, obj.mesh)
        if det is None:
            out.append(v)
            continue
        proj, _ = cv2.projectPoints(det.object_points_m, pose[0], pose[1], kmat, dist)
        bias = dict(zip(det.corner_ids.tolist(), det.image_points_px - proj.reshape(-1, 2),
                        strict=True))
        keep = [i for i, c in enumerate(v.corner_ids.tolist()) if c in bias]
        if len(keep) < 6:
            out.append(v)
            continue
        b = np.array([bias[c] for c in v.corner_ids[keep].tolist()])
        biases.append(b)
        out.append(BoardView(v.name, v.turntable_angle_deg, v.mounting,
                             v.object_points_m[keep], v.image_points_px[keep] - b,
                             v.corner_ids[keep], v.image_shape))
    rms = float(np.sqrt(np.mean(np.concatenate(biases) ** 2))) if biases else 0.0
    return out, rms
