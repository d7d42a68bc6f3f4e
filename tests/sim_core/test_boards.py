"""Calibration boards as scene objects: geometry, materials, the board frame."""

from __future__ import annotations

import numpy as np
import pytest

from sim_core.boards import board_corners_m, board_size_m, board_triangles, object_from_board
from sim_core.errors import SceneError
from sim_core.scene import build_scene
from sim_core.scene_spec import ObjectSpec, parse_scene_spec

CHARUCO = {"kind": "charuco_board", "squares_x": 5, "squares_y": 7, "square_m": 0.10,
           "marker_m": 0.06}


def _board(mesh=CHARUCO):
    return ObjectSpec.model_validate({"name": "b", "mesh": mesh}).mesh


@pytest.mark.parametrize("mesh", [CHARUCO, {"kind": "checkerboard", "squares_x": 7,
                                             "squares_y": 5, "square_m": 0.05,
                                             "margin_m": 0.02}])
def test_the_triangles_tile_the_board_exactly(mesh):
    b = _board(mesh)
    tris, white = board_triangles(b)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                axis=1)
    w, h = board_size_m(b)
    m = b.margin_m
    assert area.sum() == pytest.approx((w + 2 * m) * (h + 2 * m), rel=1e-12)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    assert np.all(normals[:, 2] > 0)  # facing +z
    assert set(np.unique(white)) == {0, 1}


def test_board_frame_maps_corners_onto_the_pattern():
    """A ChArUco corner is where four squares meet: in the object frame, on a cell edge."""
    b = _board()
    pts, ids = board_corners_m(b)
    assert len(ids) == 4 * 6
    m = object_from_board(b)
    local = pts @ m[:3, :3].T + m[:3, 3]
    # First inner corner: one square right of and one square below the top-left corner.
    assert local[0] == pytest.approx([-0.25 + 0.1, 0.35 - 0.1, 0.0])
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3)) and np.linalg.det(m[:3, :3]) > 0


def test_a_board_brings_its_own_two_materials():
    spec = parse_scene_spec({
        "camera": {"pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}},
        "objects": [{"name": "b", "mesh": CHARUCO, "pose": {"rotation_deg": [90, 0, 0]}},
                    {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [3, 3]},
                     "material": "black-flannel", "pose": {"position_m": [0, 1, 0],
                                                           "rotation_deg": [90, 0, 0]}}]})
    scene = build_scene(spec)
    assert len(scene.materials) == 3
    albedo = [getattr(m, "albedo", None) for m in scene.materials[:2]]
    assert albedo == [0.04, 0.85]
    assert set(np.unique(scene.material_index[scene.object_index == 0])) == {0, 1}
    assert set(np.unique(scene.material_index[scene.object_index == 1])) == {2}


def test_material_rules_for_boards_and_other_meshes():
    with pytest.raises(SceneError, match="brings its own materials"):
        parse_scene_spec({"camera": {"pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}},
                          "objects": [{"name": "b", "mesh": CHARUCO, "material": "black-flannel"}]})
    with pytest.raises(SceneError, match="material"):
        parse_scene_spec({"camera": {"pose": {"position_m": [0, -1, 0], "look_at_m": [0, 0, 0]}},
                          "objects": [{"name": "r", "mesh": {"kind": "box",
                                                             "size_m": [1, 1, 1]}}]})
    with pytest.raises(ValueError, match="marker_m must be smaller"):
        _board({**CHARUCO, "marker_m": 0.2})
