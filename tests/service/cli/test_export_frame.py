"""``toftwin export frame``: frame folders as NeXus HDF5 (read back with h5py, one frame and a
stack) and as a PLY point cloud (read back with trimesh); what it refuses, naming the option."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from service.cli import app
from sim_core import frame_io
from sim_core.pipeline import save_frame, simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import small_example

runner = CliRunner()


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Two simulated frame folders of the corner (16 px wide, an ideal sensor: every pixel that
    sees a wall is valid), at different seeds."""
    scene = small_example("corner", width=16)
    root = tmp_path_factory.mktemp("frames")
    return [save_frame(root / f"f{seed}", simulate(scene, RenderRequest(
        RenderSettings(integrator="direct", spp=1, seed=seed), ideal=True)), scene_name="corner")
            for seed in (1, 2)]


def _flat(text: str) -> str:
    return " ".join(text.split())


def test_one_frame_and_a_stack_as_hdf5(folders, tmp_path):
    res = runner.invoke(app, ["export", "frame", str(folders[0]), "--to", "hdf5",
                              "--out", str(tmp_path / "one.h5")])
    assert res.exit_code == 0, res.stderr
    with h5py.File(tmp_path / "one.h5", "r") as h5, np.load(folders[0] / "frame.npz") as npz:
        np.testing.assert_array_equal(h5["entry/range/data"][()], npz["range_m"])
    res = runner.invoke(app, ["export", "frame", *map(str, folders), "--to", "hdf5",
                              "--out", str(tmp_path / "sub" / "two.nxs")])
    assert res.exit_code == 0, res.stderr
    with h5py.File(tmp_path / "sub" / "two.nxs", "r") as h5:
        assert h5["entry/depth/data"].shape[0] == 2
        for i, folder in enumerate(folders):
            np.testing.assert_array_equal(h5["entry/depth/data"][i],
                                          frame_io.read_frame(folder).image.depth_z_m)
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["two.nxs"]  # no temporary


def test_a_frame_as_ply_in_the_world_frame(folders, tmp_path):
    out = tmp_path / "points.ply"
    res = runner.invoke(app, ["export", "frame", str(folders[0]), "--to", "ply", "--frame",
                              "world", "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    frame = frame_io.read_frame(folders[0])
    n = int((frame.image.valid & np.isfinite(frame.image.range_m)).sum())
    assert n > 100 and f"{n} points (world frame)" in _flat(res.stdout)
    assert len(trimesh.load(out).vertices) == n


@pytest.mark.parametrize(("extra", "says"), [
    (["--to", "obj"], "--to: 'obj'; allowed: hdf5, ply"),
    (["--to", "ply", "--frame", "lab"], "--frame: 'lab'; allowed: camera, world"),
    (["--to", "hdf5", "--out-as", "x"], "No such option"),
])
def test_bad_options_are_refused_naming_them(folders, tmp_path, extra, says):
    res = runner.invoke(app, ["export", "frame", str(folders[0]), "--out",
                              str(tmp_path / "x.h5"), *extra])
    assert res.exit_code == 2 and says in _flat(res.stderr), res.stderr
    assert not (tmp_path / "x.h5").exists()


def test_what_it_refuses_leaves_an_existing_file_as_it_was(folders, tmp_path):
    out = tmp_path / "kept.ply"
    out.write_bytes(b"mine")
    cases = [
        ([str(folders[0]), "--to", "ply", "--out", str(out)], "exists; use --force"),
        ([str(folders[0]), "--to", "hdf5", "--out", str(out)], "a .h5 or .hdf5 or .nxs file"),
        ([*map(str, folders), "--to", "ply", "--out", str(out), "--force"],
         "folders: 2 given; a PLY holds one frame"),
        ([str(tmp_path / "nowhere"), "--to", "hdf5", "--out", str(tmp_path / "n.h5")],
         "is not a frame folder"),
        ([str(folders[0]), "--to", "hdf5", "--out", str(tmp_path)], "a .h5 or .hdf5"),
    ]
    for args, says in cases:
        res = runner.invoke(app, ["export", "frame", *args])
        assert res.exit_code == 2 and says in _flat(res.stderr), (args, res.stderr)
    assert out.read_bytes() == b"mine"
    res = runner.invoke(app, ["export", "frame", str(folders[0]), "--to", "ply", "--out",
                              str(out), "--force"])
    assert res.exit_code == 0 and out.read_bytes().startswith(b"ply\n")


def test_a_damaged_or_empty_folder_is_refused_naming_it(folders, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    cut = tmp_path / "cut"
    cut.mkdir()
    for f in folders[0].iterdir():
        (cut / f.name).write_bytes(f.read_bytes())
    data = (cut / "frame.npz").read_bytes()
    (cut / "frame.npz").write_bytes(data[: len(data) // 2])
    for folder, says in ((empty, "holds none of frame.npz, raw.npz, depth_points.npz"),
                         (cut, "cannot be read: BadZipFile")):
        res = runner.invoke(app, ["export", "frame", str(folder), "--to", "hdf5", "--out",
                                  str(tmp_path / "x.h5")])
        assert res.exit_code == 2 and f"folders: '{folder}'" in _flat(res.stderr), res.stderr
        assert says in _flat(res.stderr), res.stderr
    assert not (tmp_path / "x.h5").exists()
