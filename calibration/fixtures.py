"""Where the calibration board sits on the turntable: its fixtures.

The board is mounted in a fixture whose pose at the turntable's zero is known: on the real rig a
jig with an index pin, in the simulated lab exactly. Boards that all contain the turntable's axis
are parallel to one line, a degenerate set for planar calibration (Sturm & Maybank), so the board
stands tilted about its horizontal axis, and the sequence uses several fixtures (tilts) that
together determine the principal point (CALIBRATION-NOTES.md).

Frames: the scene's world frame (z up, the turntable's axis along z through the origin in the
examples); a board object lies in its local xy plane facing +z (:mod:`sim_core.boards`). At the
turntable's zero a fixture turns the board to face the camera (its local +z towards the camera's
side of the axis, its local +y up, tilted back by ``tilt_deg``) and puts its centre
``centre_height_m`` above the axis point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sim_core import boards
from sim_core.geometry import rotation_matrix_xyz_deg
from sim_core.scene_spec import ObjectSpec, SceneSpec


@dataclass(frozen=True)
class BoardFixture:
    """One way of mounting the board (or any flat plate, a material sample) on the turntable.

    Attributes
    ----------
    name : str
        Label of the fixture (``"tilt+30"``): the views it gives form one mounting.
    tilt_deg : float
        Rotation of the board about its horizontal axis; positive tilts its top away from the
        camera.
    centre_height_m : float
        Height of the board's centre above the turntable's axis point [m]. The default keeps
        the default board (500 mm tall) clear of the table at a tilt of 0.
    towards_camera_m : float
        Horizontal distance of the board's centre from the axis, towards the camera, at the
        turntable's zero [m]. A board off the axis sweeps across the image as the table turns
        and comes closer to the camera, so its corners reach the image's edges and its lower
        half, which a board on the axis never does (the table hides everything below it):
        this is what determines the principal point and the distortion.
    """

    name: str
    tilt_deg: float
    centre_height_m: float = 0.28
    towards_camera_m: float = 0.0

    @property
    def instruction(self) -> str:
        """The fixture in words, for the operator."""
        where = (f", {self.towards_camera_m * 1e3:.0f} mm off the axis towards the camera"
                 if self.towards_camera_m else " over the axis")
        return (f"fixture '{self.name}': board tilted {self.tilt_deg:+g} deg, its centre "
                f"{self.centre_height_m * 1e3:.0f} mm above the table{where}")


def board_object(board: dict, fixture: BoardFixture, spec: SceneSpec,
                 name: str = "calibration_board") -> ObjectSpec:
    """The board as a scene object in ``fixture`` at the turntable's zero (world frame).

    The board faces the camera of ``spec`` at the turntable's zero: its normal points from the
    axis towards the camera, projected on the horizontal plane.
    """
    return fixture_object(board, fixture, spec, name)


def fixture_object(mesh: dict, fixture: BoardFixture, spec: SceneSpec, name: str,
                   material: Any = None) -> ObjectSpec:
    """Any flat plate (a board, a material sample) as a scene object in ``fixture``.

    Parameters
    ----------
    mesh : dict
        A mesh spec lying in its local xy plane and facing its local +z: a board
        (``charuco_board``, ``checkerboard``: they bring their own materials) or a
        ``rectangle``.
    fixture : BoardFixture
    spec : SceneSpec
        The nominal scene (the camera's pose, the turntable's axis).
    name : str
    material : MaterialSpec, str or None
        The plate's material (a preset name or a material spec); None for a board.

    Returns
    -------
    ObjectSpec
        On the turntable, at its pose at the turntable's zero (world frame), facing the camera
        as :func:`board_object` describes.
    """
    yaw = _facing_yaw_deg(spec)
    rot = (90.0 - fixture.tilt_deg, 0.0, yaw)
    c = np.asarray(spec.turntable.axis_point_m if spec.turntable else (0.0, 0.0, 0.0))
    facing = np.array([np.sin(np.radians(yaw)), -np.cos(np.radians(yaw)), 0.0])  # to camera
    pos = c + np.array([0.0, 0.0, fixture.centre_height_m]) + fixture.towards_camera_m * facing
    data: dict[str, Any] = {
        "name": name, "mesh": mesh, "on_turntable": True,
        "pose": {"position_m": [float(v) for v in pos], "rotation_deg": list(rot)},
    }
    if material is not None:
        data["material"] = material
    return ObjectSpec.model_validate(data)


def _facing_yaw_deg(spec: SceneSpec) -> float:
    """Rotation about world z that turns a board facing -y to face the camera."""
    from sim_core.scene import build_camera

    cam = build_camera(spec).position_m
    c = np.asarray(spec.turntable.axis_point_m if spec.turntable else (0.0, 0.0, 0.0))
    d = cam - c
    # A board rotated by rotation_deg x = 90 faces -y; the yaw turns -y towards (dx, dy).
    return float(np.degrees(np.arctan2(d[0], -d[1])))


def world_from_board(board: dict, fixture: BoardFixture, spec: SceneSpec) -> np.ndarray:
    """4x4 pose of OpenCV's board frame in the world at the turntable's (true) zero.

    ``object_from_board`` (:func:`sim_core.boards.object_from_board`) takes OpenCV's board frame
    (origin at a corner, z into the board) to the object's local frame; the fixture's pose takes
    that to the world.
    """
    obj = board_object(board, fixture, spec)
    m = np.eye(4)
    m[:3, :3] = rotation_matrix_xyz_deg(obj.pose.rotation_deg)
    m[:3, 3] = obj.pose.position_m
    return m @ boards.object_from_board(obj.mesh)
