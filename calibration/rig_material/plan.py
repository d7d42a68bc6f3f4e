"""The material sweep's plan and its sample: a flat plate on the turntable (issue 14, §2).

The sample is a square plate of the material, mounted like the calibration board
(:class:`calibration.fixtures.BoardFixture`: one home for how plates sit on the turntable),
upright, facing the camera at the turntable's zero, centred on the axis at the camera's height.
The sweep turns it through :attr:`MaterialSweepPlan.angles_deg`; at each angle the rig captures
the camera's light alone (the solar simulator's shutter closed) and, when the plan has a solar
level, with the solar simulator's shutter open.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.angles import AngleLimits, angle_range, check_angles, parse_angles
from calibration.fixtures import BoardFixture, fixture_object
from sim_core.errors import InvalidInputError
from sim_core.lights import SUNS_RANGE
from sim_core.scene_spec import ObjectSpec, SceneSpec

#: the sample's object name in the scene (the simulated lab's operator mounts it by this name)
SAMPLE_NAME = "material_sample"
#: default sweep: -70 ... 70 deg every 5 deg
DEFAULT_ANGLES_DEG: tuple[float, ...] = angle_range(-70.0, 70.0, 5.0, field="angles_deg")
#: the sample's turntable angles [deg]: beyond, the plate is seen edge-on
SAMPLE_ANGLE_RANGE_DEG: tuple[float, float] = (-85.0, 85.0)
#: the sample's turntable angles as :func:`sample_angles` allows them
SAMPLE_ANGLE_LIMITS = AngleLimits(*SAMPLE_ANGLE_RANGE_DEG,
                                  why_range="beyond, the plate is seen edge-on")


@dataclass(frozen=True)
class MaterialSweepPlan:
    """What the material sweep captures and how the slices are cut.

    Attributes
    ----------
    angles_deg : tuple of float
        Reported turntable angles [deg], 1 to 721, each in [-85, 85]: beyond, the plate is seen
        edge-on (:func:`sample_angles`).
    size_m : float
        Side of the square sample [m], in [0.02, 0.5].
    frames_per_state : int
        Frames averaged per rig state (2-64: the spread of the frames is the samples'
        uncertainty).
    solar_suns : float
        Set level of the solar simulator for the solar slice [sun]: 0 (no solar slice) or in
        the lamp's range (:data:`sim_core.lights.SUNS_RANGE`). The lowest level keeps most
        pixels below SBI.
    bin_deg : float
        Width of the angle bins the plate's pixels are grouped in [deg], in [0.1, 5]. A plate
        seen from 1 m spans about 10 deg of viewing angle: each turntable angle gives several
        rows of the slice.
    edge_margin_px : int
        Pixels of the plate's outline left out (optics blur, a fraction of a pixel of pose
        error), 1-20.
    min_pixels_per_bin : int
        Fewest pixels a row is averaged over, 3-1000.
    reference_albedo : float
        Albedo of the twin's reference Lambertian plate, in (0, 1].
    """

    angles_deg: tuple[float, ...] = DEFAULT_ANGLES_DEG
    size_m: float = 0.2
    frames_per_state: int = 4
    solar_suns: float = 0.8
    bin_deg: float = 1.0
    edge_margin_px: int = 3
    min_pixels_per_bin: int = 12
    reference_albedo: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "angles_deg", sample_angles(self.angles_deg, "angles_deg"))
        _bounded("size_m", self.size_m, 0.02, 0.5)
        _bounded("frames_per_state", self.frames_per_state, 2, 64)
        if self.solar_suns != 0.0:
            _bounded("solar_suns", self.solar_suns, *SUNS_RANGE)
        _bounded("bin_deg", self.bin_deg, 0.1, 5.0)
        _bounded("edge_margin_px", self.edge_margin_px, 1, 20)
        _bounded("min_pixels_per_bin", self.min_pixels_per_bin, 3, 1000)
        if not (math.isfinite(self.reference_albedo) and 0.0 < self.reference_albedo <= 1.0):
            raise InvalidInputError("reference_albedo", f"{self.reference_albedo!r} is outside "
                                    "(0, 1]")

    @property
    def with_solar(self) -> bool:
        """Whether the sweep captures the solar slice."""
        return self.solar_suns > 0.0

    @property
    def n_captures(self) -> int:
        """Rig states the sweep visits (for progress)."""
        return len(self.angles_deg) * (2 if self.with_solar else 1)

    @property
    def n_steps(self) -> int:
        """Steps of the whole procedure (for progress): the captures, the twin's reference of
        each angle, the slices and fit."""
        return self.n_captures + len(self.angles_deg) + 1


def sample_angles(angles: str | Sequence[float], field: str) -> tuple[float, ...]:
    """The sweep's angles [deg]: text in the grammar of :func:`calibration.angles.parse_angles`
    (``"-70:70:5"``, ``"-30, 0, 30"``) or numbers; 1 to 721, each in
    :data:`SAMPLE_ANGLE_RANGE_DEG`; an input error names ``field``.

    >>> sample_angles("-10:10:5", "--angles")
    (-10.0, -5.0, 0.0, 5.0, 10.0)
    """
    if isinstance(angles, str):
        return parse_angles(angles, field=field, limits=SAMPLE_ANGLE_LIMITS)
    return check_angles(angles, field=field, limits=SAMPLE_ANGLE_LIMITS)


def sample_fixture(spec: SceneSpec) -> BoardFixture:
    """Upright, on the axis, its centre at the camera's height (the camera's z)."""
    from sim_core.scene import build_camera

    axis_z = spec.turntable.axis_point_m[2] if spec.turntable else 0.0
    height = float(build_camera(spec).position_m[2] - axis_z)
    return BoardFixture("material-sample", 0.0, centre_height_m=height)


def sample_object(spec: SceneSpec, size_m: float, material: Any) -> ObjectSpec:
    """The sample plate in its fixture (:func:`sample_fixture`) at the turntable's zero.

    ``material`` is the plate's material in the scene: the sample's prior for the procedure
    (which never relies on it: it renders a reference Lambertian instead), the true material
    where the simulated lab mounts it.
    """
    mesh = {"kind": "rectangle", "size_m": [float(size_m), float(size_m)]}
    return fixture_object(mesh, sample_fixture(spec), spec, SAMPLE_NAME, material=material)


def _bounded(name: str, value: float, lo: float, hi: float) -> None:
    if not (np.isfinite(value) and lo <= value <= hi):
        raise InvalidInputError(name, f"{value!r} is outside [{lo:g}, {hi:g}]")
