"""Simulation jobs carry their meshes; settings fail fast; the frame store is atomic."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import trimesh
from pydantic import ValidationError

from service.compute.jobs import make_job, run_job
from service.settings import Settings
from service.store.frame_files import FrameStore
from sim_core.scene_spec import parse_scene_spec

pytestmark = pytest.mark.timeout(60)


def test_a_job_carries_its_mesh_files_to_the_worker(tmp_path):
    mesh_dir = tmp_path / "meshes"
    mesh_dir.mkdir()
    trimesh.creation.box(extents=(0.4, 0.4, 0.4)).export(mesh_dir / "cube.stl")
    spec = parse_scene_spec({
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]},
                   "width_px": 24, "height_px": 16},
        "objects": [{"name": "cube", "mesh": {"kind": "file", "path": "cube.stl"},
                     "material": "black-flannel", "pose": {"position_m": [0, 0, 1.2]}}],
    })
    job = make_job(spec, mesh_dir, turntable_deg=None, solar_suns=None, spp=1, seed=0,
                   threads=1, ideal=True)
    shutil.rmtree(mesh_dir)  # the worker must not need the service's files
    result = run_job(job)
    assert set(result.files) == {"frame.npz", "frame.json", "grey.png", "depth.png"}
    centre = result.image.range_m[6:10, 10:14]
    assert np.nanmedian(centre) == pytest.approx(1.0, abs=0.01)  # the cube's front face
    assert (result.object_id[6:10, 10:14] == 0).all()


def test_settings_refuse_placeholder_tokens_and_unknown_executors(tmp_path):
    for token in ("changethis", "short"):
        with pytest.raises(ValidationError, match="token"):
            Settings(token=token, data_dir=tmp_path)
    with pytest.raises(ValidationError, match="dask://HOST:PORT"):
        Settings(token="a-real-token-123", executor="spark://x")
    s = Settings(token="a-real-token-123", executor="dask://10.0.0.5:8786", data_dir=tmp_path)
    assert s.dask_address == "tcp://10.0.0.5:8786" and s.host == "127.0.0.1"
    assert s.database == f"sqlite:///{tmp_path / 'toftwin.db'}"


def test_settings_come_from_the_environment_or_a_file(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFTWIN_TOKEN", "from-the-environment")
    monkeypatch.setenv("TOFTWIN_WORKERS", "3")
    assert Settings.load().workers == 3
    env = tmp_path / "toftwin.env"
    env.write_text("TOFTWIN_PORT=9001\nTOFTWIN_SIMULATED=true\n")
    s = Settings.load(env, workers=2)
    assert (s.port, s.simulated, s.workers) == (9001, True, 2)


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
