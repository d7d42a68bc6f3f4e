"""The frame store is atomic: whole frames or nothing, orphans swept."""

from __future__ import annotations

import pytest

from service.store.frame_files import FrameStore

pytestmark = pytest.mark.timeout(60)


def test_the_frame_store_publishes_whole_frames_and_sweeps_orphans(tmp_path):
    store = FrameStore(tmp_path)
    a = "a" * 32
    store.save_files(a, {"frame.json": b"{}", "frame.npz": b"x"})
    assert sorted(p.name for p in (tmp_path / a).iterdir()) == ["frame.json", "frame.npz"]
    with pytest.raises(ValueError, match="unexpected frame file"):
        store.save_files("b" * 32, {"../evil": b""})
    (tmp_path / f".partial-{'c' * 32}").mkdir()  # a crash in the middle of a write
    (tmp_path / ("d" * 32)).mkdir()  # written, never committed
    assert sorted(store.sweep({a})) == sorted([f".partial-{'c' * 32}", "d" * 32])
    assert [p.name for p in tmp_path.iterdir()] == [a]
    with pytest.raises(KeyError):
        store.path("../../etc")


def test_a_damaged_depth_points_file_is_named(tmp_path):
    """A measured frame of royale's processed depth that does not read names its
    ``depth_points.npz`` (the diagnosis looked at the raw frames' files only)."""
    import numpy as np

    from service.errors import DamagedFileError
    from sim_core.camera import CAMERA_PRESETS, Camera, Intrinsics
    from sim_core.processed_depth import ProcessedDepthFrame

    p = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
    intr = Intrinsics(p["width_px"], p["height_px"], p["fx_px"], p["fy_px"], p["cx_px"],
                      p["cy_px"], (0.0,) * 5)
    shape = intr.shape
    z = np.full(shape, 1.5, np.float32)
    frame = ProcessedDepthFrame(np.zeros(shape, np.float32), np.zeros(shape, np.float32), z,
                                np.full(shape, 0.01, np.float32), np.full(shape, 100.0,
                                                                          np.float32),
                                np.ones(shape, np.float32), np.array([60.24e6]), 500e-6)
    store = FrameStore(tmp_path)
    frame_id, _, _ = store.save_measured(frame, Camera(intr, np.eye(4)), {})
    assert store.read(frame_id).image is not None
    path = tmp_path / frame_id / "depth_points.npz"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(DamagedFileError, match=r"frame file damaged: depth_points\.npz"):
        store.read(frame_id)
