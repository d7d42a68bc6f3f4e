"""Frames in the field's forms, read back with the libraries that consume them: NeXus HDF5
(sim_core.nexus) with h5py and nexusformat, PLY point clouds (sim_core.frame_points) with
trimesh; and the camera a simulated frame.json now records (intrinsics and pose)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import trimesh
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from nexusformat.nexus import nxload

from sim_core import frame_io
from sim_core.camera import pixel_to_camera_direction
from sim_core.errors import InvalidInputError
from sim_core.frame_io import pose_from_meta
from sim_core.frame_points import frame_points, write_points_ply
from sim_core.nexus import NexusFrameStack, write_frame_nexus
from sim_core.pipeline import save_frame, simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import EXAMPLES, small_example


@pytest.fixture(scope="module")
def scene_and_folder(tmp_path_factory):
    """The ground-test scene 32 px wide, simulated with a sensor (so with a raw frame) and saved."""
    scene = small_example("satellite_ground_test", width=32)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=2, seed=3)))
    out = save_frame(tmp_path_factory.mktemp("frames") / "sim", frame, scene_name="sat")
    return scene, out


@pytest.fixture(scope="module")
def measured(scene_and_folder, tmp_path_factory):
    """A measured frame folder of the simulated frame's raw frame, as the store writes it."""
    scene, folder = scene_and_folder
    raw = frame_io.read_frame(folder).raw
    out = tmp_path_factory.mktemp("frames") / "measured"
    frame_io.write_measured(out, raw, scene.camera, {"frame_id": "a" * 32,
                                                     "rig": {"turntable_deg": 20.0}})
    return out


def test_a_simulated_frame_json_records_its_camera_s_intrinsics_and_pose(scene_and_folder):
    scene, folder = scene_and_folder
    meta = json.loads((folder / frame_io.FRAME_JSON).read_text())
    assert frame_io.intrinsics_from_meta(meta, scene.camera.intrinsics.shape) == \
        scene.camera.intrinsics
    np.testing.assert_array_equal(pose_from_meta(meta), scene.camera.world_from_camera)


def test_measured_frame_is_what_the_folder_reads_back_as(scene_and_folder, measured):
    scene, folder = scene_and_folder
    raw = frame_io.read_frame(folder).raw
    built = frame_io.measured_frame(raw, scene.camera, {"frame_id": "a" * 32,
                                                        "rig": {"turntable_deg": 20.0}})
    back = frame_io.read_frame(measured)
    assert built.meta == back.meta and built.grey_full_scale == back.grey_full_scale
    for name in ("range_m", "depth_z_m", "amplitude", "intensity", "valid"):
        np.testing.assert_array_equal(getattr(built.image, name), getattr(back.image, name))
    assert set(built.arrays) == set(back.arrays)


@pytest.mark.parametrize("kind", ["simulated", "measured"])
def test_a_frame_s_nexus_file_reads_with_h5py_and_nexusformat(
        kind, scene_and_folder, measured, tmp_path):
    scene, sim_folder = scene_and_folder
    folder = sim_folder if kind == "simulated" else measured
    frame = frame_io.read_frame(folder)
    path = write_frame_nexus(tmp_path / "frame.h5", frame, {"depth_mse": 2.5})
    with np.load(folder / frame_io.FRAME_NPZ) as npz:
        stored = {k: npz[k] for k in npz.files}
    with h5py.File(path, "r") as h5:
        assert h5.attrs["default"] == "entry" and h5["entry"].attrs["NX_class"] == "NXentry"
        depth = h5["entry/depth"]
        assert depth.attrs["NX_class"] == "NXdata" and depth.attrs["signal"] == "data"
        assert list(depth.attrs["axes"]) == ["y", "x"]
        assert depth["data"].attrs["units"] == "m"
        np.testing.assert_array_equal(depth["data"][()], stored["depth_z_m"])
        np.testing.assert_array_equal(h5["entry/range/data"][()], stored["range_m"])
        np.testing.assert_array_equal(h5["entry/grey/data"][()], stored["grey_8bit"])
        np.testing.assert_array_equal(h5["entry/valid/data"][()], stored["valid"].astype(np.uint8))
        assert h5["entry/amplitude/data"].attrs["units"] == "DN"  # a sensor's frame
        np.testing.assert_array_equal(h5["entry/raw/data"][()], frame.raw.phase_images)
        cam = h5["entry/camera"]
        intr = scene.camera.intrinsics
        np.testing.assert_allclose(cam["camera_matrix"][()], [[intr.fx_px, 0, intr.cx_px],
                                                             [0, intr.fy_px, intr.cy_px],
                                                             [0, 0, 1]])
        assert int(cam["width_px"][()]) == intr.width_px
        assert h5["entry/metrics/depth_mse"][()] == 2.5
        assert json.loads(h5["entry/metadata/frame_json"][()].decode()) == frame.meta
        assert h5["entry/metadata/kind"][()].decode() == kind
        pose = cam["world_from_camera"][()]
        if kind == "simulated":  # the renderer's pose; a measured frame's is not known
            np.testing.assert_array_equal(pose, scene.camera.world_from_camera)
        else:
            assert np.isnan(pose).all()
            assert h5["entry/rig/turntable_deg"][()] == 20.0
    root = nxload(str(path))
    signal = root.entry.depth.nxsignal
    assert signal.nxname == "data" and str(signal.attrs["units"]) == "m"
    assert [a.nxname for a in root.entry.depth.nxaxes] == ["y", "x"]
    np.testing.assert_array_equal(signal.nxvalue, stored["depth_z_m"])
    assert [a.nxname for a in root.entry.raw.nxaxes] == ["frequency", "phase_step", "y", "x"]
    np.testing.assert_array_equal(root.entry.phase.frequency.nxvalue, stored["frequencies_hz"])


def test_a_stack_holds_frames_along_a_frame_axis_and_refuses_another_form(
        scene_and_folder, measured, tmp_path):
    _, folder = scene_and_folder
    sim = frame_io.read_frame(folder)
    meas = frame_io.read_frame(measured)
    with NexusFrameStack(tmp_path / "stack.h5") as stack:
        assert stack.append(meas, {"pose_index": 0}, entry="measured") == 0
        assert stack.append(meas, {"pose_index": 1}, entry="measured") == 1
        assert stack.append(sim, {"pose_index": 0}, entry="simulated") == 0
        ideal = frame_io.Frame("simulated", sim.image, sim.arrays, sim.meta,
                               sim.grey_full_scale, None)  # no raw frame: another form
        with pytest.raises(InvalidInputError, match="one form"):
            stack.append(ideal, entry="simulated")
        # a frame of another shape (its raw frame cut to two frequencies' worth of rows)
        cut = frame_io.Frame("simulated", sim.image, sim.arrays, sim.meta, sim.grey_full_scale,
                             sim.raw.__class__(**{**sim.raw.__dict__, "phase_images":
                                                  sim.raw.phase_images[..., :-1, :]}))
        with pytest.raises(InvalidInputError, match="one shape"):
            stack.append(cut, entry="simulated")
        assert stack.entry_count("measured") == 2 and stack.entry_count("simulated") == 1
    root = nxload(str(tmp_path / "stack.h5"))
    assert root.attrs["default"] == "measured"
    data = root.measured.depth.nxsignal
    assert data.shape == (2, *sim.image.range_m.shape)
    assert [a.nxname for a in root.measured.depth.nxaxes] == ["frame", "y", "x"]
    np.testing.assert_array_equal(data.nxvalue[1], meas.image.depth_z_m)
    np.testing.assert_array_equal(root.measured.metrics.pose_index.nxvalue, [0, 1])
    # the refused frames left nothing behind: every group of the entry holds one frame
    with h5py.File(tmp_path / "stack.h5", "r") as h5:
        lengths = {name: h5["simulated"][name][k].shape[0] for name in h5["simulated"]
                   if isinstance(h5["simulated"][name], h5py.Group)
                   for k in h5["simulated"][name] if k in ("data", "pose_index", "frame_id")}
    assert set(lengths.values()) == {1}, lengths


def test_a_stack_keeps_a_metric_first_seen_at_a_later_frame(scene_and_folder, tmp_path):
    _, folder = scene_and_folder
    frame = frame_io.read_frame(folder)
    with NexusFrameStack(tmp_path / "s.h5") as stack:
        stack.append(frame, {})  # a result without a comparison
        stack.append(frame, {"grey_ssim": 0.5, "depth_mse": None})
        stack.append(frame)
    with h5py.File(tmp_path / "s.h5", "r") as h5:
        np.testing.assert_array_equal(h5["entry/metrics/grey_ssim"][()], [np.nan, 0.5, np.nan])
        assert np.isnan(h5["entry/metrics/depth_mse"][()]).all()
        assert h5["entry/depth/data"].shape[0] == 3


@pytest.mark.parametrize("point_frame", ["camera", "world"])
def test_a_frame_s_ply_reads_with_trimesh_point_for_point(scene_and_folder, tmp_path,
                                                          point_frame):
    scene, folder = scene_and_folder
    frame = frame_io.read_frame(folder)
    n = write_points_ply(tmp_path / "points.ply", frame, point_frame)
    cloud = trimesh.load(tmp_path / "points.ply")
    keep = frame.image.valid & np.isfinite(frame.image.range_m)
    assert isinstance(cloud, trimesh.PointCloud) and len(cloud.vertices) == n == keep.sum()
    props = cloud.metadata["_ply_raw"]["vertex"]["data"]
    i = n // 2
    row, col = int(props["row"][i]), int(props["column"][i])
    d = pixel_to_camera_direction(scene.camera.intrinsics, np.array([col]), np.array([row]))[0]
    expected = frame.image.range_m[row, col] * d
    # the point's depth along the optical axis is the frame's depth there
    assert expected[2] == pytest.approx(frame.image.depth_z_m[row, col], rel=1e-12)
    if point_frame == "world":
        m = scene.camera.world_from_camera
        expected = m[:3, :3] @ expected + m[:3, 3]
    np.testing.assert_allclose(cloud.vertices[i], expected, rtol=0, atol=1e-6)  # float32
    assert props["grey"][i] == frame.grey_8bit()[row, col]
    assert np.isfinite(props["noise_m"]).all() and (props["noise_m"] >= 0).all()


def test_the_world_frame_of_a_frame_without_a_pose_is_refused_naming_the_field(measured,
                                                                               tmp_path):
    frame = frame_io.read_frame(measured)
    with pytest.raises(InvalidInputError, match="world_from_camera") as err:
        write_points_ply(tmp_path / "p.ply", frame, "world")
    assert err.value.field == "--frame"
    assert not (tmp_path / "p.ply").exists()


@settings(max_examples=40, deadline=None)
@given(matrix=st.one_of(
    st.none(), st.just("text"), st.just([[1.0, 0.0], [0.0, 1.0]]),
    st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4),
             min_size=4, max_size=4).filter(lambda m: m != np.eye(4).tolist())))
def test_a_pose_is_a_rigid_4x4_or_refused_naming_frame_json(matrix):
    if matrix is None:
        assert pose_from_meta({"world_from_camera": matrix}) is None
        return
    with pytest.raises(InvalidInputError) as err:
        pose_from_meta({"world_from_camera": matrix})
    assert err.value.field == "frame.json" and "world_from_camera" in str(err.value)


@settings(max_examples=40, deadline=None)
@given(angles=st.tuples(*[st.floats(-np.pi, np.pi)] * 3),
       t=st.tuples(*[st.floats(-10, 10)] * 3))
def test_a_rigid_pose_is_taken_as_it_is(angles, t):
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", angles).as_matrix()
    m[:3, 3] = t
    np.testing.assert_array_equal(pose_from_meta({"world_from_camera": m.tolist()}), m)


def test_points_of_an_all_invalid_frame_are_none(scene_and_folder, tmp_path):
    _, folder = scene_and_folder
    frame = frame_io.read_frame(folder)
    image = frame.image.__class__(**{**frame.image.__dict__,
                                     "valid": np.zeros_like(frame.image.valid)})
    empty = frame_io.Frame(frame.kind, image, frame.arrays, frame.meta, frame.grey_full_scale,
                           frame.raw)
    assert frame_points(empty).xyz_camera_m.shape == (0, 3)
    assert write_points_ply(tmp_path / "empty.ply", empty) == 0
    assert b"element vertex 0\n" in (tmp_path / "empty.ply").read_bytes()
    assert trimesh.load(tmp_path / "empty.ply").is_empty


def _with_image(frame, **arrays):
    image = frame.image.__class__(**{**frame.image.__dict__, **arrays})
    return frame_io.Frame(frame.kind, image, frame.arrays, frame.meta, frame.grey_full_scale,
                          frame.raw)


def test_the_noise_estimate_is_the_range_noise_s_standard_deviation(scene_and_folder):
    """Independent Gaussian noise of 10 mm on a flat range image: the median noise_m is
    10 mm within 10 %."""
    _, folder = scene_and_folder
    frame = frame_io.read_frame(folder)
    rng = np.random.default_rng(4)
    shape = frame.image.range_m.shape
    noisy = _with_image(frame, range_m=1.0 + rng.normal(0.0, 0.010, shape),
                        valid=np.ones(shape, dtype=bool))
    assert np.median(frame_points(noisy).noise_m) == pytest.approx(0.010, rel=0.10)


def test_world_points_lie_on_the_scene_s_surfaces(tmp_path):
    """The satellite on its turntable at 40 deg: the world-frame points of the pixels that see
    it lie on its posed triangles, and not on the same triangles posed 10 deg off (an
    independent check of pose, intrinsics and the turntable's frame)."""
    spec_angle, other = 40.0, 30.0
    scene = small_example("satellite_ground_test", width=64, turntable_deg=spec_angle)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=2, seed=1),
                                          ideal=True))
    back = frame_io.read_frame(save_frame(tmp_path / "f", frame))
    points = frame_points(back)
    spec = yaml.safe_load((EXAMPLES / "satellite_ground_test.yaml").read_text())
    on_table = {i for i, o in enumerate(spec["objects"]) if o.get("on_turntable")}
    sees = np.isin(back.arrays["object_id"][points.row_px, points.column_px], list(on_table))
    world = points.xyz_m("world")[sees]
    sample = world[:: max(1, len(world) // 200)]
    mine = np.isin(scene.object_index, list(on_table))
    posed = np.asarray(scene.triangles_m, dtype=np.float64)[mine]
    elsewhere = small_example("satellite_ground_test", width=64, turntable_deg=other)
    unposed = np.asarray(elsewhere.triangles_m, dtype=np.float64)[mine]
    near = _distance_to_triangles(sample, posed)
    far = _distance_to_triangles(sample, unposed)
    assert len(sample) > 30, len(sample)
    # edge pixels mix the satellite and the background: a median and a share, not every point
    assert np.median(near) < 2e-3 and np.median(far) > 3 * np.median(near)
    assert np.mean(near < 2e-3) > 0.6 and np.mean(far < 2e-3) < 0.3


def _distance_to_triangles(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Each point's distance to the nearest triangle whose plane it projects into (inf where
    it projects into none): plane distance and a barycentric inside test, in numpy."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=1)
    keep = area2 > 1e-12
    a, b, c, n = a[keep], b[keep], c[keep], n[keep] / area2[keep, None]
    out = np.full(len(points), np.inf)
    for i, p in enumerate(points):
        d = np.einsum("ij,ij->i", p - a, n)
        q = p - d[:, None] * n
        inside = np.ones(len(a), dtype=bool)
        for u, v in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= -1e-9
        if inside.any():
            out[i] = np.abs(d[inside]).min()
    return out


def test_camera_points_project_back_to_their_pixels_through_opencv(tmp_path):
    """A camera with distortion: cv2.projectPoints (OpenCV's own model) takes each camera-frame
    point back to the pixel it came from."""
    import cv2

    scene = small_example("corner", width=48)
    intr = scene.camera.intrinsics
    spec_distortion = (-0.12, 0.03, 0.001, -0.002, 0.0)
    distorted = intr.__class__(intr.width_px, intr.height_px, intr.fx_px, intr.fy_px,
                               intr.cx_px + 1.5, intr.cy_px - 0.7, spec_distortion)
    meta = {"intrinsics": frame_io.intrinsics_dict(distorted)}
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=1),
                                          ideal=True))
    base = frame_io.read_frame(save_frame(tmp_path / "f", frame))
    tilted = frame_io.Frame(base.kind, base.image, base.arrays, {**base.meta, **meta},
                            base.grey_full_scale, base.raw)
    points = frame_points(tilted)
    k = np.array([[distorted.fx_px, 0, distorted.cx_px], [0, distorted.fy_px, distorted.cy_px],
                  [0, 0, 1]])
    uv, _ = cv2.projectPoints(points.xyz_camera_m, np.zeros(3), np.zeros(3), k,
                              np.asarray(spec_distortion))
    uv = uv.reshape(-1, 2)
    assert len(uv) > 100
    np.testing.assert_allclose(uv[:, 0], points.column_px, atol=1e-4)
    np.testing.assert_allclose(uv[:, 1], points.row_px, atol=1e-4)


@pytest.mark.parametrize(("change", "says"), [
    ({"intrinsics": {"width_px": 32, "height_px": 24, "fy_px": 30.0, "cx_px": 15.5,
                     "cy_px": 11.5}}, "intrinsics.fx_px: Field required"),
    ({"intrinsics": {"width_px": 32, "height_px": 24, "fx_px": 0.0, "fy_px": 30.0,
                     "cx_px": 15.5, "cy_px": 11.5}}, "intrinsics.fx_px: Input should be greater"),
    ({"intrinsics": {"width_px": 99, "height_px": 24, "fx_px": 30.0, "fy_px": 30.0,
                     "cx_px": 15.5, "cy_px": 11.5}}, "intrinsics of a 99 x 24 image"),
    ({"world_from_camera": [[1.0, 0.0], [0.0, 1.0]]}, "world_from_camera is not"),
])
def test_a_frame_json_out_of_its_form_is_refused_naming_it(scene_and_folder, tmp_path, change,
                                                            says):
    _, folder = scene_and_folder
    frame = frame_io.read_frame(folder)
    bad = frame_io.Frame(frame.kind, frame.image, frame.arrays, {**frame.meta, **change},
                         frame.grey_full_scale, frame.raw)
    for write in (lambda: write_frame_nexus(tmp_path / "x.h5", bad),
                  lambda: write_points_ply(tmp_path / "x.ply", bad)):
        with pytest.raises(InvalidInputError, match=says) as err:
            write()
        assert err.value.field == "frame.json"
    assert not any(tmp_path.iterdir())


def test_a_frame_json_of_an_unknown_kind_is_refused(scene_and_folder, tmp_path):
    _, folder = scene_and_folder
    copy = tmp_path / "copy"
    copy.mkdir()
    for f in folder.iterdir():
        (copy / f.name).write_bytes(f.read_bytes())
    meta = json.loads((copy / "frame.json").read_text())
    (copy / "frame.json").write_text(json.dumps({**meta, "kind": "synthetic"}))
    with pytest.raises(InvalidInputError, match="kind 'synthetic'; allowed: measured"):
        frame_io.read_frame(copy)
