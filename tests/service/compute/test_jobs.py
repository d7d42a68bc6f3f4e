"""Simulation jobs carry their meshes."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import trimesh

from service.compute.jobs import make_job, run_job
from sim_core.render_request import request_from_spec
from sim_core.scene_spec import RenderSpec, parse_scene_spec

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
    job = make_job(spec, mesh_dir, turntable_deg=None, solar_suns=None,
                   request=request_from_spec(spec.render, spp=1, seed=0, threads=1, ideal=True))
    shutil.rmtree(mesh_dir)  # the worker must not need the service's files
    result = run_job(job)
    assert set(result.files) == {"frame.npz", "frame.json", "grey.png", "depth.png"}
    centre = result.image.range_m[6:10, 10:14]
    assert np.nanmedian(centre) == pytest.approx(1.0, abs=0.01)  # the cube's front face
    assert (result.object_id[6:10, 10:14] == 0).all()


def test_a_job_carries_its_goniometer_tables_to_the_worker(tmp_path):
    """A tabulated material reads its table on the worker too (issue 14): the job packs it."""
    from tests.sim_core.materials.test_tabulated import goniometer_table, write_csv

    scene_dir = tmp_path / "scene"
    scene_dir.mkdir()
    write_csv(scene_dir / "gonio.csv", goniometer_table("white-matte-tile", 5.0, retro_gap_deg=0.0))
    data = {
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]},
                   "width_px": 24, "height_px": 16},
        "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [3, 3]},
                     "material": {"kind": "tabulated", "params": {"table": "gonio.csv"}},
                     "pose": {"position_m": [0, 0, 1.0], "rotation_deg": [180, 0, 0]}}],
    }
    request = request_from_spec(RenderSpec(), spp=4, seed=0, threads=1, ideal=True)
    job = make_job(parse_scene_spec(data), scene_dir, turntable_deg=None, solar_suns=None,
                   request=request)
    analytic = {**data, "objects": [{**data["objects"][0], "material": "white-matte-tile"}]}
    reference = run_job(make_job(parse_scene_spec(analytic), scene_dir, turntable_deg=None,
                                 solar_suns=None, request=request))
    shutil.rmtree(scene_dir)  # the worker must not need the service's files
    result = run_job(job)
    ratio = np.nanmedian(result.image.amplitude / reference.image.amplitude)
    # the table is the tile it was sampled from (measured up to retro-reflection, which the
    # camera looks along here: its light sits at the camera)
    assert ratio == pytest.approx(1.0, abs=0.1)
