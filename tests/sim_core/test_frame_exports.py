"""Frames in the field's forms, read back with the libraries that consume them: NeXus HDF5
(sim_core.nexus) with h5py and nexusformat, PLY point clouds (sim_core.frame_points) with
trimesh; and the camera a simulated frame.json now records (intrinsics and pose)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from nexusformat.nexus import nxload

from sim_core import frame_io
from sim_core.camera import pixel_to_camera_direction
from sim_core.errors import InvalidInputError
from sim_core.frame_points import frame_points, write_points_ply
from sim_core.nexus import NexusFrameStack, frame_pose, write_frame_nexus
from sim_core.pipeline import save_frame, simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import small_example


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
    np.testing.assert_array_equal(frame_pose(meta), scene.camera.world_from_camera)


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
        assert stack.entry_count("measured") == 2 and stack.entry_count("simulated") == 1
    root = nxload(str(tmp_path / "stack.h5"))
    assert root.attrs["default"] == "measured"
    data = root.measured.depth.nxsignal
    assert data.shape == (2, *sim.image.range_m.shape)
    assert [a.nxname for a in root.measured.depth.nxaxes] == ["frame", "y", "x"]
    np.testing.assert_array_equal(data.nxvalue[1], meas.image.depth_z_m)
    np.testing.assert_array_equal(root.measured.metrics.pose_index.nxvalue, [0, 1])
    assert root.simulated.raw.data.shape[0] == 1  # the refused frame left nothing behind


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
             min_size=4, max_size=4)))
def test_a_pose_is_a_finite_4x4_or_none(matrix):
    pose = frame_pose({"world_from_camera": matrix})
    if pose is not None:
        assert pose.shape == (4, 4) and np.isfinite(pose).all()


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
