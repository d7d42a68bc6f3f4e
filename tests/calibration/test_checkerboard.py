"""A rendered plain checkerboard at about 1 m is found by OpenCV where it projects.

The board must be wholly in view (``findChessboardCornersSB`` finds all inner corners or none):
7 x 6 squares of 60 mm (0.42 m x 0.36 m; squares_x + squares_y odd, so its orientation is
unambiguous) in a fixture whose centre is 0.24 m above the turntable's axis point clears the
table at +-30 deg tilt and stays inside the image over +-45 deg of yaw. A 5 x 7 board of 100 mm
squares in the default fixture reaches below the table top, and is not found.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.board_detection import detect_board, detect_checkerboard
from calibration.fixtures import BoardFixture, board_object, world_from_board
from sim_core.geometry import axis_angle_matrix
from sim_core.pipeline import expose_light, render_light
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from tests.sim_core.scenes import EXAMPLES

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
BOARD = {"kind": "checkerboard", "squares_x": 7, "squares_y": 6, "square_m": 0.06}
CENTRE_HEIGHT_M = 0.24
#: corner RMS against the true projection [px] (measured 0.11-0.15 px over the sweep)
RMS_BOUND_PX = 0.2


def _views(board, tilt, angle, centre_height_m=CENTRE_HEIGHT_M):
    """Noise-free and noisy amplitude of one render, and the corners' true projection."""
    fixture = BoardFixture("f", tilt, centre_height_m)
    obj = board_object(board, fixture, SPEC)
    spec = SPEC.model_copy(update={"objects": [o for o in SPEC.objects if not o.on_turntable]
                                   + [obj]})
    scene = build_scene(spec, EXAMPLES, turntable_deg=angle, solar_suns=0.0)
    rendered = render_light(scene,
                            RenderRequest(RenderSettings(integrator="direct", spp=16, seed=1)))
    clean = expose_light(scene, rendered, noise=False).image.amplitude
    noisy = expose_light(scene, rendered, noise_rng=np.random.default_rng(5)).image.amplitude
    turn = np.eye(4)
    turn[:3, :3] = axis_angle_matrix((0, 0, 1), np.radians(angle))
    cam_from_board = (np.linalg.inv(scene.camera.world_from_camera) @ turn
                      @ world_from_board(board, fixture, SPEC))
    return obj.mesh, clean, noisy, cam_from_board, scene.camera.intrinsics


def _rms_px(det, cam_from_board, k):
    p = det.object_points_m @ cam_from_board[:3, :3].T + cam_from_board[:3, 3]
    truth = np.stack([k.fx_px * p[:, 0] / p[:, 2] + k.cx_px,
                      k.fy_px * p[:, 1] / p[:, 2] + k.cy_px], axis=1)
    return float(np.sqrt(np.mean(np.sum((det.image_points_px - truth) ** 2, axis=1))))


@pytest.mark.parametrize(("tilt", "angle"), [(30.0, -45.0), (-30.0, 30.0), (0.0, 0.0)])
def test_a_rendered_checkerboard_is_found_where_it_projects(tilt, angle):
    mesh, clean, noisy, cfb, k = _views(BOARD, tilt, angle)
    n = (BOARD["squares_x"] - 1) * (BOARD["squares_y"] - 1)
    for amplitude in (clean, noisy):
        det = detect_board(amplitude, mesh)
        assert det is not None and len(det.corner_ids) == n
        # Every corner paired with its own board point (OpenCV's order fixed by the colours).
        assert _rms_px(det, cfb, k) < RMS_BOUND_PX


def test_a_board_cut_by_the_table_is_not_found():
    big = {"kind": "checkerboard", "squares_x": 5, "squares_y": 7, "square_m": 0.10}
    mesh, clean, _, _, _ = _views(big, 30.0, 0.0, centre_height_m=0.16)
    assert detect_checkerboard(clean, mesh) is None
    assert detect_checkerboard(np.zeros((171, 224)), mesh) is None


@pytest.mark.slow
def test_the_whole_sweep_is_found():
    """3 tilts x 7 yaws (-45..45 deg), noise-free and noisy: measured 21/21 and 21/21."""
    found, rms = {"clean": 0, "noisy": 0}, []
    for tilt in (30.0, -30.0, 0.0):
        for angle in (-45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0):
            mesh, clean, noisy, cfb, k = _views(BOARD, tilt, angle)
            for name, amplitude in (("clean", clean), ("noisy", noisy)):
                det = detect_board(amplitude, mesh)
                if det is not None:
                    found[name] += 1
                    rms.append(_rms_px(det, cfb, k))
    assert found["clean"] >= 20 and found["noisy"] >= 20, found
    assert max(rms) < RMS_BOUND_PX
