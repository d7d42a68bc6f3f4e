"""One board view: the corners found in one averaged capture, and where the rig was."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BoardView:
    """Detected corners of one view of the board.

    Attributes
    ----------
    name : str
        ``"<fixture>@<angle>"``.
    turntable_angle_deg : float
        The angle the turntable reported [deg].
    mounting : str
        The fixture the board was in (its views share one board-to-turntable pose).
    object_points_m : (n, 3) float64
        Corners in OpenCV's board frame [m].
    image_points_px : (n, 2) float64
        Their detected image positions [px].
    corner_ids : (n,) int
    image_shape : (H, W)
    """

    name: str
    turntable_angle_deg: float
    mounting: str
    object_points_m: np.ndarray = field(repr=False)
    image_points_px: np.ndarray = field(repr=False)
    corner_ids: np.ndarray = field(repr=False)
    image_shape: tuple[int, int] = (171, 224)
