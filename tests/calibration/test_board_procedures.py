"""Board detection, intrinsics and the turntable axis: accuracy on known truth, clear refusals."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.board_detection import detect_board
from calibration.board_views import BoardView
from calibration.fixtures import BoardFixture, board_object, world_from_board
from calibration.intrinsics import calibrate_intrinsics
from calibration.rig_sequence import DEFAULT_BOARD, DEFAULT_FIXTURES
from calibration.turntable_axis import fit_turntable_axis
from sim_core.boards import board_corners_m
from sim_core.errors import InvalidInputError
from sim_core.geometry import axis_angle_matrix
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_camera, build_scene
from sim_core.scene_spec import load_scene_spec
from tests.sim_core.scenes import EXAMPLES

BOARD = DEFAULT_BOARD
SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")


def _rot(axis, point, angle_deg):
    m = np.eye(4)
    r = axis_angle_matrix(axis, np.radians(angle_deg))
    m[:3, :3] = r
    m[:3, 3] = np.asarray(point) - r @ np.asarray(point)
    return m


@pytest.mark.parametrize(("tilt", "off_m", "angle"),
                         [(30.0, 0.2, -30.0), (-30.0, 0.2, 15.0), (0.0, 0.4, -20.0)])
def test_a_rendered_board_is_found_where_it_projects(tilt, off_m, angle):
    fixture = BoardFixture("f", tilt, centre_height_m=0.26, towards_camera_m=off_m)
    obj = board_object(BOARD, fixture, SPEC)
    spec = SPEC.model_copy(update={"objects": [o for o in SPEC.objects if not o.on_turntable]
                                   + [obj]})
    scene = build_scene(spec, EXAMPLES, turntable_deg=angle, solar_suns=0.0)
    frame = simulate(scene,
                     RenderRequest(RenderSettings(integrator="direct", spp=64, seed=1), ideal=True))
    det = detect_board(frame.image.amplitude, obj.mesh)
    assert det is not None and len(det.corner_ids) >= 10
    cam_from_board = (np.linalg.inv(scene.camera.world_from_camera)
                      @ _rot((0, 0, 1), (0, 0, 0), angle) @ world_from_board(BOARD, fixture,
                                                                               SPEC))
    p = det.object_points_m @ cam_from_board[:3, :3].T + cam_from_board[:3, 3]
    k = scene.camera.intrinsics
    truth = np.stack([k.fx_px * p[:, 0] / p[:, 2] + k.cx_px,
                      k.fy_px * p[:, 1] / p[:, 2] + k.cy_px], axis=1)
    err = np.hypot(*(det.image_points_px - truth).T)
    assert np.sqrt(np.mean(err**2)) < 0.2, err


def test_no_board_no_detection():
    assert detect_board(np.zeros((171, 224)), board_object(BOARD, BoardFixture("f", 0), SPEC)
                        .mesh) is None


# -- synthetic views: a known camera, a turntable, OpenCV's projection ----------------------
def _synthetic(seed, fixtures_used=DEFAULT_FIXTURES, angles=range(-55, 56, 5), noise_px=0.05,
               axis=(0.01, -0.008, 1.0), point=(0.003, -0.002, 0.0), zero_deg=0.4):
    """Views of the default plan, as OpenCV projects the corners, with corner noise; the table
    (z = 0) hides what is below it."""
    rng = np.random.default_rng(seed)
    cam = build_camera(SPEC)
    k = np.array([[208.33 * rng.uniform(0.97, 1.03), 0, 111.5 + rng.uniform(-3, 3)],
                  [0, 208.33 * rng.uniform(0.97, 1.03), 85.0 + rng.uniform(-3, 3)], [0, 0, 1]])
    dist = np.array([rng.uniform(-0.15, 0.05), rng.uniform(-0.05, 0.05),
                     rng.uniform(-1e-3, 1e-3), rng.uniform(-1e-3, 1e-3), 0.0])
    board = board_object(BOARD, BoardFixture("f", 0.0), SPEC).mesh
    pts, ids = board_corners_m(board)
    views, fixtures = [], {}
    for fx in fixtures_used:
        fixtures[fx.name] = world_from_board(BOARD, fx, SPEC)
        for a in angles:
            w = _rot(axis / np.linalg.norm(axis), point, a + zero_deg) @ fixtures[fx.name]
            cfb = np.linalg.inv(cam.world_from_camera) @ w
            img, _ = cv2.projectPoints(pts, cv2.Rodrigues(cfb[:3, :3])[0], cfb[:3, 3], k, dist)
            img = img.reshape(-1, 2) + rng.normal(0, noise_px, (len(pts), 2))
            facing = cfb[:3, 2] @ cfb[:3, 3] / np.linalg.norm(cfb[:3, 3])
            inside = ((img[:, 0] > 2) & (img[:, 0] < 221) & (img[:, 1] > 2) & (img[:, 1] < 168)
                      & ((pts @ w[:3, :3].T + w[:3, 3])[:, 2] > 0.0) & (abs(facing) > 0.5))
            if inside.sum() < 6:
                continue
            views.append(BoardView(f"{fx.name}@{a}", float(a), fx.name, pts[inside],
                                   img[inside], ids[inside], (171, 224)))
    return views, fixtures, k, dist, cam


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_intrinsics_and_axis_recover_a_known_rig(seed):
    views, fixtures, k, _, cam = _synthetic(seed)
    res = calibrate_intrinsics(views, (171, 224))
    got = res.intrinsics
    assert got.fx_px == pytest.approx(k[0, 0], rel=0.005)
    assert got.fy_px == pytest.approx(k[1, 1], rel=0.005)
    assert abs(got.cx_px - k[0, 2]) < 0.5 and abs(got.cy_px - k[1, 2]) < 0.5
    assert res.rms_px < 0.3 and not res.rejected
    axis = fit_turntable_axis(views, res.poses, cam.world_from_camera, fixtures,
                              intrinsics=res.intrinsics)
    true_axis = np.array([0.01, -0.008, 1.0]) / np.linalg.norm([0.01, -0.008, 1.0])
    assert np.degrees(np.arccos(np.clip(axis.axis_direction @ true_axis, -1, 1))) < 0.2
    d = axis.axis_point_m - np.array([0.003, -0.002, 0.0])
    assert np.linalg.norm(d - (d @ true_axis) * true_axis) < 0.002
    # Free poses only start the joint adjustment (the next test holds the issue's 0.1 deg);
    # OpenCV 4.10, the floor, lands 0.10-0.14 deg off here on its own.
    assert axis.zero_offset_deg == pytest.approx(0.4, abs=0.4)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_camera_and_turntable_adjusted_together_reach_the_issue_targets(seed):
    """The bundle adjustment of camera and turntable together: issue 13's targets (0.5 %,
    0.5 px, 0.2 deg, 2 mm, 0.1 deg) on views with 0.05 px of corner noise, and closer than the
    free-pose calibration it starts from."""
    views, fixtures, k, _, cam = _synthetic(seed)
    free = calibrate_intrinsics(views, (171, 224))
    axis = fit_turntable_axis(views, free.poses, cam.world_from_camera, fixtures,
                              intrinsics=free.intrinsics, refine_intrinsics=True)
    got = axis.intrinsics
    assert got.fx_px == pytest.approx(k[0, 0], rel=0.005)
    assert got.fy_px == pytest.approx(k[1, 1], rel=0.005)
    pp_joint = np.hypot(got.cx_px - k[0, 2], got.cy_px - k[1, 2])
    pp_free = np.hypot(free.intrinsics.cx_px - k[0, 2], free.intrinsics.cy_px - k[1, 2])
    assert abs(got.cx_px - k[0, 2]) < 0.5 and abs(got.cy_px - k[1, 2]) < 0.5
    assert pp_joint < pp_free, (pp_joint, pp_free)
    assert axis.reprojection_rms_px < 0.1
    true_axis = np.array([0.01, -0.008, 1.0]) / np.linalg.norm([0.01, -0.008, 1.0])
    assert np.degrees(np.arccos(np.clip(axis.axis_direction @ true_axis, -1, 1))) < 0.2
    d = axis.axis_point_m - np.array([0.003, -0.002, 0.0])
    assert np.linalg.norm(d - (d @ true_axis) * true_axis) < 0.002
    assert axis.zero_offset_deg == pytest.approx(0.4, abs=0.1)
    assert set(axis.poses) == {v.name for v in views if v.name in free.poses}


def test_refining_the_intrinsics_needs_a_start():
    views, fixtures, _, _, cam = _synthetic(7)
    free = calibrate_intrinsics(views, (171, 224))
    with pytest.raises(InvalidInputError, match=r"turntable\.intrinsics"):
        fit_turntable_axis(views, free.poses, cam.world_from_camera, fixtures,
                           refine_intrinsics=True)


def test_an_outlier_view_is_rejected_with_its_reason():
    views, _, _, _, _ = _synthetic(4)
    bad = views[7]
    views[7] = BoardView(bad.name, bad.turntable_angle_deg, bad.mounting, bad.object_points_m,
                         bad.image_points_px + np.random.default_rng(0).normal(0, 3.0,
                                                                              bad.image_points_px
                                                                              .shape),
                         bad.corner_ids, bad.image_shape)
    res = calibrate_intrinsics(views, (171, 224))
    assert [r["name"] for r in res.rejected] == [bad.name]
    assert "reprojection RMS" in res.rejected[0]["reason"]


@pytest.mark.parametrize(("n", "line", "from_preset"),
                         [(6, "row", False), (9, "column", False), (7, "row", True)])
def test_a_view_whose_corners_lie_on_one_line_is_rejected_with_its_reason(n, line,
                                                                         from_preset):
    """A view of one row (or column) of corners has no homography, OpenCV's start without a
    guess (a user's photos: OpenCV asserted on it): it is rejected naming why, and the
    calibration goes on without it."""
    views, _, _, _, _ = _synthetic(4)
    good = views[0]
    square_m = 0.05
    k = np.arange(n, dtype=np.float64) * square_m
    obj = np.stack([k, np.zeros(n), np.zeros(n)] if line == "row"
                   else [np.zeros(n), k, np.zeros(n)], axis=1)
    img = np.stack([40.0 + 10.0 * np.arange(n), np.full(n, 80.0)], axis=1)
    views.append(BoardView("one_line", 0.0, good.mounting, obj, img, np.arange(n),
                           good.image_shape))
    res = calibrate_intrinsics(views, (171, 224), guess_from_preset=from_preset,
                               refuse_degenerate=from_preset)
    assert [r["name"] for r in res.rejected] == ["one_line"]
    assert "lie on one line" in res.rejected[0]["reason"]
    assert "one_line" not in res.per_view_rms_px


def test_boards_that_all_contain_one_line_are_refused():
    """Upright boards on one axis: every normal is perpendicular to the axis (degenerate)."""
    upright = tuple(f for f in DEFAULT_FIXTURES if f.tilt_deg == 0.0)
    views, _, _, _, _ = _synthetic(5, fixtures_used=upright, axis=(0.0, 0.0, 1.0))
    with pytest.raises(InvalidInputError, match="degenerate set"):
        calibrate_intrinsics(views, (171, 224))


def test_too_few_views_and_a_narrow_sweep_are_refused():
    views, fixtures, _, _, cam = _synthetic(6)
    with pytest.raises(InvalidInputError, match="at least 6"):
        calibrate_intrinsics(views[:3], (171, 224))
    res = calibrate_intrinsics(views, (171, 224))
    narrow = [v for v in views if abs(v.turntable_angle_deg) <= 5]
    with pytest.raises(InvalidInputError, match=r"spans 10\.0 deg"):
        fit_turntable_axis(narrow, res.poses, cam.world_from_camera, fixtures)
    two = [v for v in views if v.turntable_angle_deg in (0.0, 30.0)]
    with pytest.raises(InvalidInputError, match="2 distinct angles"):
        fit_turntable_axis(two, res.poses, cam.world_from_camera, fixtures)
