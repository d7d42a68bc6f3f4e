"""``toftwin calibrate intrinsics``: images in, intrinsics, per-view report and verdicts out.

Fast: image loading of every format, refusals naming the option, a synthetic camera (a
chessboard drawn through a known lens) recovered through the command line. Slow: rendered
ChArUco views of random realities' ToF cameras (the issue's 0.5 % / 0.5 px targets) and
OpenCV's public photographs against OpenCV's published calibration.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibration.photo_intrinsics import (
    calibrate_photos,
    image_sources,
    load_grey,
    make_board,
    write_outputs,
)
from sim_core.errors import InvalidInputError
from tests.calibration.opencv_samples import PUBLISHED, SQUARES, opencv_samples_dir
from tests.calibration.realities import random_reality, reality_seeds

# -- a synthetic camera: a chessboard drawn through a known lens ------------------------------
TRUE_K = np.array([[600.0, 0.0, 322.0], [0.0, 598.0, 236.0], [0.0, 0.0, 1.0]])
TRUE_D = np.array([-0.12, 0.05, 4e-4, -3e-4, 0.0])
SQ = (10, 7)  # squares
SQUARE_M = 0.03


def _draw_view(rvec, tvec, shape=(480, 640), supersample=4, dist=TRUE_D) -> np.ndarray:
    """The board (SQ squares of SQUARE_M, white margin) seen through TRUE_K, TRUE_D at pose
    (rvec, tvec) (board frame: OpenCV's, origin at the pattern's top-left corner) [8-bit]."""
    h, w = shape[0] * supersample, shape[1] * supersample
    u, v = np.meshgrid((np.arange(w) + 0.5) / supersample - 0.5,
                       (np.arange(h) + 0.5) / supersample - 0.5)
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, TRUE_K, dist).reshape(-1, 2)
    r = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    t = np.asarray(tvec, dtype=np.float64)
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    n = r[:, 2]  # the board's plane: n . (X - t) = 0
    s = (n @ t) / (rays @ n)
    board = (rays * s[:, None] - t) @ r  # board-frame coordinates
    i = np.floor(board[:, 0] / SQUARE_M)
    j = np.floor(board[:, 1] / SQUARE_M)
    inside = (i >= 0) & (i < SQ[0]) & (j >= 0) & (j < SQ[1])
    grey = np.where(inside & ((i + j) % 2 == 0), 20.0, 230.0).reshape(h, w)
    return cv2.resize(grey, (shape[1], shape[0]), interpolation=cv2.INTER_AREA).astype(np.uint8)


def _synthetic_poses(n=16, seed=4):
    rng = np.random.default_rng(seed)
    centre = np.array([SQ[0] * SQUARE_M / 2, SQ[1] * SQUARE_M / 2, 0.0])
    poses = []
    for _ in range(n):
        rvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2)])
        r = cv2.Rodrigues(rvec)[0]
        where = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04),
                          rng.uniform(0.45, 0.6)])
        poses.append((rvec, where - r @ centre))
    return poses


@pytest.fixture(scope="module")
def synthetic_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("synthetic")
    for k, (rvec, tvec) in enumerate(_synthetic_poses()):
        cv2.imwrite(str(d / f"view{k:02d}.png"), _draw_view(rvec, tvec))
    return d


# -- loading ---------------------------------------------------------------------------------
def test_every_format_loads_as_one_grey_image(tmp_path):
    rng = np.random.default_rng(0)
    grey16 = rng.integers(0, 65535, (30, 40), dtype=np.uint16)
    colour = rng.integers(0, 255, (30, 40, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "a16.png"), grey16)
    cv2.imwrite(str(tmp_path / "b.jpg"), colour)
    cv2.imwrite(str(tmp_path / "c.tif"), grey16)
    cv2.imwrite(str(tmp_path / "d8.png"), colour[:, :, 0])
    a = load_grey(tmp_path / "a16.png")
    assert a.dtype == np.uint16 and np.array_equal(a, grey16)
    assert load_grey(tmp_path / "b.jpg").shape == (30, 40)
    assert np.array_equal(load_grey(tmp_path / "c.tif"), grey16)
    assert np.array_equal(load_grey(tmp_path / "d8.png"), colour[:, :, 0])
    assert [p.name for p in image_sources([tmp_path])] == ["a16.png", "b.jpg", "c.tif",
                                                           "d8.png"]


def test_a_frame_folder_is_read_with_the_projects_reader(tmp_path):
    """``frame.npz`` (as :func:`sim_core.frame_io.write_simulated` writes it) gives the
    frame's amplitude; the folder and its frame.npz name the same view."""
    from sim_core.frame_io import FRAME_NPZ, image_arrays
    from sim_core.tof import ToFImage

    amp = np.random.default_rng(1).uniform(0, 5, (12, 16))
    image = ToFImage(range_m=np.ones((12, 16)), depth_z_m=np.ones((12, 16)), amplitude=amp,
                     intensity=amp, phase_rad=np.zeros((1, 12, 16)),
                     valid=np.ones((12, 16), bool), frequencies_hz=np.array([60e6]))
    frame = tmp_path / "frame_000"
    frame.mkdir()
    np.savez(frame / FRAME_NPZ, **image_arrays(image, 5.0))
    assert np.allclose(load_grey(frame), amp)
    assert image_sources([frame / FRAME_NPZ]) == [frame]
    assert image_sources([tmp_path]) == [frame]


# -- refusals --------------------------------------------------------------------------------
@pytest.mark.parametrize(("args", "field", "says"), [
    (("chessboard", "10", 25.0), "--squares", "WxH"),
    (("chessboard", "2x7", 25.0), "--squares", "3-40"),
    (("chessboard", "10x7", 0.0), "--square-mm", "above 0"),
    (("chessboard", "10x7", -3.0), "--square-mm", "above 0"),
    (("round", "10x7", 25.0), "--board", "charuco, chessboard"),
    (("charuco", "5x5", 100.0, None, "DICT_4X4_50"), "--marker-mm", "marker side"),
    (("charuco", "5x5", 100.0, 120.0, "DICT_4X4_50"), "--marker-mm", "below --square-mm"),
    (("charuco", "5x5", 100.0, 60.0, "DICT_9X9_1"), "--dictionary", "DICT_4X4_50"),
])
def test_bad_options_name_the_option_and_the_allowed_values(args, field, says):
    with pytest.raises(InvalidInputError) as err:
        make_board(*args)
    assert err.value.field == field and says in str(err.value)


def test_missing_files_and_folders_without_images_are_refused(tmp_path):
    with pytest.raises(InvalidInputError, match="does not exist"):
        image_sources([tmp_path / "nothing.png"])
    with pytest.raises(InvalidInputError, match="holds no image"):
        image_sources([tmp_path])
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InvalidInputError, match="not a supported image"):
        image_sources([tmp_path / "notes.txt"])


def test_no_usable_views_says_how_many_and_why(tmp_path):
    for k in range(7):
        cv2.imwrite(str(tmp_path / f"blank{k}.png"), np.full((480, 640), 128, np.uint8))
    with pytest.raises(InvalidInputError) as err:
        calibrate_photos([tmp_path], make_board("chessboard", "10x7", 30.0))
    text = str(err.value)
    assert err.value.field == "IMAGES"
    assert "0 of 7 images" in text and "at least 6" in text and "board not found" in text


# -- a known camera --------------------------------------------------------------------------
def test_a_synthetic_camera_is_recovered_and_judged(synthetic_dir, tmp_path):
    cal = calibrate_photos([synthetic_dir], make_board("chessboard", "10x7", 30.0))
    p = cal.parameters
    assert abs(p["fx_px"] / TRUE_K[0, 0] - 1) < 0.005 and abs(p["fy_px"] / TRUE_K[1, 1] - 1) < 0.005
    assert all(v.used and v.corners == 54 and v.rms_px < 0.2 for v in cal.views)
    truth = {"fx_px": TRUE_K[0, 0], "fy_px": TRUE_K[1, 1], "cx_px": TRUE_K[0, 2],
             "cy_px": TRUE_K[1, 2], **dict(zip(("k1", "k2", "p1", "p2"), TRUE_D, strict=False))}
    for name, value in truth.items():  # every key determined, its error within its std
        key = f"camera.{name}" if name.endswith("_px") else f"camera.distortion.{name}"
        verdict = cal.verdicts[key]
        assert verdict.determined, (key, verdict)
        assert abs(p[name] - value) < 3 * verdict.std, (key, p[name], value, verdict)
    assert set(cal.verdicts) == {"camera.fx_px", "camera.fy_px", "camera.cx_px", "camera.cy_px",
                                 "camera.distortion.k1", "camera.distortion.k2",
                                 "camera.distortion.p1", "camera.distortion.p2"}
    paths = write_outputs(tmp_path / "out", cal)
    fs = cv2.FileStorage(str(paths["opencv"]), cv2.FILE_STORAGE_READ)
    k = fs.getNode("camera_matrix").mat()
    assert np.allclose(k[0, 0], p["fx_px"]) and fs.getNode("image_width").real() == 640
    assert fs.getNode("distortion_coefficients").mat().shape == (1, 5)
    fs.release()
    import yaml

    data = yaml.safe_load(paths["calibration"].read_text())
    record = data["provenance"]["procedures"]["photo_intrinsics"]
    assert record["image_size_px"] == [640, 480] and len(record["views"]) == 16
    assert data["camera"]["cx_px"] == pytest.approx(p["cx_px"])
    # a valid calibration file of a 640 x 480 camera, which no 224 x 171 scene takes
    from sim_core.errors import SceneError
    from sim_core.scene_spec import SceneSpec
    from sim_core.twin_apply import apply_to_spec
    from sim_core.twin_file import load_calibration

    loaded = load_calibration(paths["calibration"])
    assert loaded.camera.image_size_px == (640, 480)
    assert loaded.camera.fx_px == pytest.approx(p["fx_px"])
    camera = {"pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}}
    with pytest.raises(SceneError, match=r"^camera\.image_size_px: .* 640 x 480 image; this "
                       r"scene's camera is 224 x 171"):
        apply_to_spec(SceneSpec.model_validate({"camera": camera}), loaded)
    wide = SceneSpec.model_validate({"camera": {**camera, "width_px": 640, "height_px": 480}})
    assert apply_to_spec(wide, loaded).camera.cx_px == pytest.approx(p["cx_px"])


@pytest.mark.parametrize(("tangential", "k3"), [(True, False), (False, False), (True, True)])
def test_the_one_step_jackknife_is_the_refitted_one(synthetic_dir, tangential, k3):
    """Each view left out: one Gauss-Newton step from the full fit gives what OpenCV's
    calibration of the other views gives, to a few percent of the jackknife's spread (the
    refit, started from the full fit, is what the one step replaced)."""
    from calibration.intrinsics import calibrate_intrinsics
    from calibration.photo_intrinsics import detect_corners, one_step_leave_outs
    from calibration.rig_verdicts import jackknife_std

    board = make_board("chessboard", "10x7", 30.0)
    views = []
    from calibration.board_views import BoardView

    for path in sorted(synthetic_dir.iterdir()):
        det = detect_corners(load_grey(path), board)
        views.append(BoardView(path.name, 0.0, "photo", det.object_points_m,
                               det.image_points_px, det.corner_ids, (480, 640)))
    full = calibrate_intrinsics(views, (480, 640), fix_k3=not k3, guess_from_preset=False,
                                refuse_degenerate=False, zero_tangential=not tangential)
    one = one_step_leave_outs(views, full, k3, tangential)
    k = full.intrinsics
    kmat = np.array([[k.fx_px, 0, k.cx_px], [0, k.fy_px, k.cy_px], [0, 0, 1]])
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | (0 if k3 else cv2.CALIB_FIX_K3)
             | (0 if tangential else cv2.CALIB_ZERO_TANGENT_DIST))
    refit = []
    for i in range(len(views)):
        rest = [v for j, v in enumerate(views) if j != i]
        _, km, d, _, _ = cv2.calibrateCamera(
            [v.object_points_m.astype(np.float32) for v in rest],
            [v.image_points_px.astype(np.float32).reshape(-1, 1, 2) for v in rest], (640, 480),
            kmat.copy(), np.asarray(k.distortion, dtype=np.float64),
            flags=flags, criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12))
        d = d.ravel()
        refit.append([km[0, 0], km[1, 1], km[0, 2], km[1, 2], d[0], d[1]]
                     + ([d[2], d[3]] if tangential else []) + ([d[4]] if k3 else []))
    refit = np.asarray(refit)
    assert one.shape == refit.shape == (len(views), 6 + 2 * tangential + k3)
    spread = jackknife_std(refit)
    assert np.all(spread > 0)
    print(f"\nlargest |one step - refit| / spread: {np.max(np.abs(one - refit) / spread):.4f}")
    assert np.all(np.abs(one - refit) <= 0.05 * spread), np.abs(one - refit) / spread
    assert np.allclose(jackknife_std(one), spread, rtol=0.05)


def test_a_lens_without_tangential_terms_gets_none(tmp_path):
    """The synthetic camera with p1 = p2 = 0: freeing them does not reduce the residual beyond
    chance, so they are held at 0 (written as 0, not determined, the test's figures in the
    reason) and every other key is determined within 3 of its standard deviations."""
    radial = TRUE_D * np.array([1.0, 1.0, 0.0, 0.0, 1.0])
    for k, (rvec, tvec) in enumerate(_synthetic_poses()):
        cv2.imwrite(str(tmp_path / f"view{k:02d}.png"), _draw_view(rvec, tvec, dist=radial))
    cal = calibrate_photos([tmp_path], make_board("chessboard", "10x7", 30.0))
    assert cal.tangential is not None and not cal.tangential.fitted
    p = cal.parameters
    assert p["p1"] == 0.0 and p["p2"] == 0.0
    for name in ("p1", "p2"):
        verdict = cal.verdicts[f"camera.distortion.{name}"]
        assert verdict.verdict == "not determined" and verdict.std is None
        assert "held at 0" in verdict.reason and "F = " in verdict.reason
    truth = {"fx_px": TRUE_K[0, 0], "fy_px": TRUE_K[1, 1], "cx_px": TRUE_K[0, 2],
             "cy_px": TRUE_K[1, 2], "k1": radial[0], "k2": radial[1]}
    for name, value in truth.items():
        key = f"camera.{name}" if name.endswith("_px") else f"camera.distortion.{name}"
        verdict = cal.verdicts[key]
        assert verdict.determined, (key, verdict)
        assert abs(p[name] - value) < 3 * verdict.std, (key, p[name], value, verdict)


def test_a_wrong_lens_model_is_unexplained(synthetic_dir):
    """The same views with distortion the model cannot follow: k1 alone drawn much stronger
    is still followed, so the images are warped by a radial term of 8th order instead."""
    board = make_board("chessboard", "10x7", 30.0)
    cal = calibrate_photos([synthetic_dir], board)
    assert cal.model.reduced_chi2 < 2.0  # the right model explains the corners
    # corners shifted by a pattern of the image position the model has no term for
    from calibration.photo_intrinsics import ModelTest, model_test

    views = []
    from calibration.board_views import BoardView

    for name in cal.result.per_view_rms_px:
        path = synthetic_dir / name
        from calibration.photo_intrinsics import detect_corners

        det = detect_corners(load_grey(path), board)
        xy = det.image_points_px.copy()
        xy[:, 0] += 0.6 * np.sin(xy[:, 1] / 480 * 2 * np.pi * 2)
        views.append(BoardView(name, 0.0, "photo", det.object_points_m, xy, det.corner_ids,
                               (480, 640)))
    from calibration.intrinsics import calibrate_intrinsics

    res = calibrate_intrinsics(views, (480, 640), guess_from_preset=False,
                               refuse_degenerate=False)
    test: ModelTest = model_test(views, res, (480, 640))
    assert test.reduced_chi2 > 2.0


def test_the_command_line_writes_the_three_files(synthetic_dir, tmp_path):
    from toftwin_cli import app

    out = tmp_path / "cal"
    res = CliRunner().invoke(app, ["calibrate", "intrinsics", str(synthetic_dir), "--board",
                                   "chessboard", "--squares", "10x7", "--square-mm", "30",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "view15.png" in res.output and "camera.fx_px" in res.output
    verdicts = json.loads((out / "verdicts.json").read_text())
    assert verdicts["camera.fx_px"]["verdict"] == "determined"
    assert (out / "calibration.yaml").is_file() and (out / "opencv_intrinsics.yml").is_file()
    bad = CliRunner().invoke(app, ["calibrate", "intrinsics", str(synthetic_dir), "--board",
                                   "charuco", "--squares", "10x7", "--square-mm", "30",
                                   "--marker-mm", "20", "--dictionary", "DICT_NOPE",
                                   "--out", str(out)])
    assert bad.exit_code == 2 and "--dictionary" in bad.output


# -- rendered views of random realities (the ToF camera) -------------------------------------
RENDER_BOARD = {"kind": "charuco_board", "squares_x": 8, "squares_y": 6, "square_m": 0.07,
                "marker_m": 0.042, "dictionary": "DICT_4X4_50"}


#: a user's board sequence in front of the ToF camera (:func:`_render_views`): views, the
#: board's distance [m], its largest tilt about either of its axes and turn about its normal [deg]
RENDER_VIEWS, RENDER_DISTANCE_M, RENDER_TILT_DEG, RENDER_TURN_DEG = 216, (0.55, 0.85), 40.0, 25.0


def _render_views(reality, out: Path, seed: int) -> None:
    """RENDER_VIEWS views of RENDER_BOARD held before the camera as a user waves it through a
    frame sequence: its centre aimed at each cell of a 3 x 3 grid over the image in turn
    (anywhere in the cell's middle 70 %), RENDER_DISTANCE_M away, tilted up to RENDER_TILT_DEG
    about both its axes and turned up to RENDER_TURN_DEG about its normal (drawn from ``[seed,
    28]``); half as 16-bit PNGs of the amplitude, half as frame folders (frame.npz). Spp 8 with
    the sensor's noise, through the reality's lens."""
    from scipy.spatial.transform import Rotation

    from sim_core.frame_io import write_simulated
    from sim_core.pipeline import simulate
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from sim_core.scene import build_camera, build_scene
    from sim_core.scene_spec import ObjectSpec, load_scene_spec
    from tests.sim_core.scenes import EXAMPLES

    spec0 = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    camera = build_camera(spec0)
    world_from_camera, k = camera.world_from_camera, camera.intrinsics
    # the board facing the camera, upright: its x along the image's, its y up, its +z to the lens
    facing = np.diag([1.0, -1.0, -1.0])
    rng = np.random.default_rng([seed, 28])
    fixed = [o for o in spec0.objects if not o.on_turntable]
    for i in range(RENDER_VIEWS):
        cell = i % 9
        u = (cell % 3 + rng.uniform(0.15, 0.85)) / 3 * k.width_px
        v = (cell // 3 + rng.uniform(0.15, 0.85)) / 3 * k.height_px
        ray = np.array([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, 1.0])
        centre_cam = rng.uniform(*RENDER_DISTANCE_M) * ray / np.linalg.norm(ray)
        tilt = Rotation.from_euler("xyz", [rng.uniform(-RENDER_TILT_DEG, RENDER_TILT_DEG),
                                           rng.uniform(-RENDER_TILT_DEG, RENDER_TILT_DEG),
                                           rng.uniform(-RENDER_TURN_DEG, RENDER_TURN_DEG)],
                                   degrees=True).as_matrix()
        board_in_world = world_from_camera[:3, :3] @ tilt @ facing
        centre_world = world_from_camera[:3, :3] @ centre_cam + world_from_camera[:3, 3]
        board = ObjectSpec(name="calibration_board", mesh=RENDER_BOARD, pose={
            "position_m": [float(x) for x in centre_world],
            "rotation_deg": [float(x) for x in Rotation.from_matrix(board_in_world)
                             .as_euler("xyz", degrees=True)]})
        scene = build_scene(spec0.model_copy(update={"objects": [*fixed, board]}), EXAMPLES,
                            turntable_deg=0.0, solar_suns=0.0, twin=reality)
        frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=8,
                                                             seed=i)),
                         noise_rng=np.random.default_rng([seed, i]))
        if i % 2:
            write_simulated(out / f"view{i:03d}", frame)
        else:
            a = np.nan_to_num(frame.image.amplitude)
            a16 = np.clip(a / np.percentile(a, 99.9) * 60000, 0, 65535)
            cv2.imwrite(str(out / f"view{i:03d}.png"), a16.astype(np.uint16))


@pytest.mark.slow
@pytest.mark.parametrize("seed", reality_seeds([154]))
def test_rendered_views_of_a_random_reality_meet_the_targets(seed, tmp_path):
    """Issue 28's targets on a random reality's ToF camera: fx, fy within 0.5 %, cx, cy within
    0.5 px, each determined; and issue 27's: a key called determined is within 3 of its
    standard deviations or within its target. CI runs reality 154 (its tangential terms, 7.9e-4
    and -5.6e-4, pulled the principal point 0.7 px off on the 54 turntable views this test
    rendered before); ``TOFTWIN_REALITY_SEEDS=151-170`` runs more (docs/calibration.md has
    their table)."""
    reality = random_reality(seed)
    _render_views(reality, tmp_path / "views", seed)
    board = make_board("charuco", "8x6", 70.0, 42.0, "DICT_4X4_50")
    cal = calibrate_photos([tmp_path / "views"], board)
    p, truth = cal.parameters, reality.camera
    used = sum(v.used for v in cal.views)
    print(f"\nreality {seed}: {used} views used; fx {100 * (p['fx_px'] / truth.fx_px - 1):+.3f} "
          f"%, fy {100 * (p['fy_px'] / truth.fy_px - 1):+.3f} %, cx "
          f"{p['cx_px'] - truth.cx_px:+.3f} px (std {cal.verdicts['camera.cx_px'].std:.3f}), cy "
          f"{p['cy_px'] - truth.cy_px:+.3f} px (std {cal.verdicts['camera.cy_px'].std:.3f}); "
          f"p1, p2 {cal.verdicts['camera.distortion.p1'].verdict}")
    assert used >= RENDER_VIEWS // 2
    assert abs(p["fx_px"] / truth.fx_px - 1) < 0.005
    assert abs(p["fy_px"] / truth.fy_px - 1) < 0.005
    assert abs(p["cx_px"] - truth.cx_px) < 0.5
    assert abs(p["cy_px"] - truth.cy_px) < 0.5
    assert not any(v.verdict == "unexplained" for v in cal.verdicts.values())
    for name in ("fx_px", "fy_px", "cx_px", "cy_px"):
        verdict = cal.verdicts[f"camera.{name}"]
        assert verdict.determined, (name, verdict)
        target = 0.5 if name.startswith("c") else 0.005 * getattr(truth, name)
        err = abs(p[name] - getattr(truth, name))
        assert err < max(3 * verdict.std, target), (name, err, verdict)


# -- OpenCV's public photographs -------------------------------------------------------------
@pytest.mark.slow
def test_opencvs_photographs_give_opencvs_published_calibration(tmp_path):
    """OpenCV's left01-14.jpg (Debian opencv-doc 4.6.0) against the calibration OpenCV's own
    test publishes (modules/python/test/test_calibration.py): focal lengths within 2 %,
    principal point within 5 px; fx, fy and the distortion determined; the principal point's
    verdict honest (its standard deviation covers the published value's distance)."""
    from toftwin_cli import app

    out = tmp_path / "cal"
    res = CliRunner().invoke(app, ["calibrate", "intrinsics", str(opencv_samples_dir()),
                                   "--board", "chessboard", "--squares",
                                   f"{SQUARES[0]}x{SQUARES[1]}", "--square-mm", "25",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    fs = cv2.FileStorage(str(out / "opencv_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    k = fs.getNode("camera_matrix").mat()
    per_view = fs.getNode("per_view_reprojection_errors").mat().ravel()
    fs.release()
    assert len(per_view) == 13 and per_view.max() < 0.3
    assert abs(k[0, 0] / PUBLISHED["fx_px"] - 1) < 0.02
    assert abs(k[1, 1] / PUBLISHED["fy_px"] - 1) < 0.02
    assert abs(k[0, 2] - PUBLISHED["cx_px"]) < 5.0 and abs(k[1, 2] - PUBLISHED["cy_px"]) < 5.0
    verdicts = json.loads((out / "verdicts.json").read_text())
    assert all(v["verdict"] != "unexplained" for v in verdicts.values())
    for key in ("camera.fx_px", "camera.fy_px", "camera.distortion.k1",
                "camera.distortion.k2", "camera.distortion.p1", "camera.distortion.p2"):
        assert verdicts[key]["verdict"] == "determined", (key, verdicts[key])
    for key, i, j, name in (("camera.cx_px", 0, 2, "cx_px"), ("camera.cy_px", 1, 2, "cy_px")):
        assert abs(k[i, j] - PUBLISHED[name]) < 3 * verdicts[key]["std"]
