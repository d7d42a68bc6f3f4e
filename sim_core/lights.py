"""Light sources: the camera's modulated point source and collimated ambient sources.

The active source follows the seed's eq. 18 (I_L = P_L / Omega_L, modulated) and the peer
paper's eq. 1 (an optional vendor table of relative intensity against the angle from the
source's axis). Ambient sources (sun, solar simulator, Earth and Moon albedo) are collimated:
they add to the DC part only (seed section 2.3.1, after eq. 21).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: level range the solar simulator (Oriel Sol3A) may be driven to, in suns; its spectral match
#: is specified near 1 sun. The one home of the range: the scene spec, the rig driver
#: (``drivers.solar_simulator.SUNS_RANGE``) and the service's requests use it.
SUNS_RANGE = (0.8, 1.2)


@dataclass(frozen=True)
class PointLight:
    """Isotropic or tabulated modulated point source.

    Attributes
    ----------
    position_m : (3,) float64
        World position.
    axis : (3,) float64
        Unit main direction of the source (the camera's optical axis by default).
    power_w : float
        Radiant power [W] (the DC part; the modulated part has the same amplitude).
    profile_angle_rad, profile_relative : (k,) float64 or None
        Relative radiant intensity against the angle from ``axis``; linear interpolation,
        zero beyond the last angle. None means isotropic. The renderer evaluates it in
        ``sim_core.render.kernels._profile_intensity`` with ``scale_w_sr``.
    """

    position_m: np.ndarray
    axis: np.ndarray
    power_w: float
    profile_angle_rad: np.ndarray | None = None
    profile_relative: np.ndarray | None = None
    #: radiant intensity per unit of relative intensity [W/sr] (P / 4 pi when isotropic)
    scale_w_sr: float = field(init=False, repr=False, default=0.0)

    def __post_init__(self) -> None:
        if self.profile_angle_rad is None:
            scale = self.power_w / (4.0 * np.pi)
        else:
            # Normalise the table so the source emits exactly power_w:
            # P = 2*pi * integral I(theta) sin(theta) dtheta.
            theta = np.linspace(0.0, np.pi, 4097)
            rel = np.interp(theta, self.profile_angle_rad, self.profile_relative, right=0.0)
            solid = 2.0 * np.pi * np.trapezoid(rel * np.sin(theta), theta)
            scale = self.power_w / solid if solid > 0.0 else 0.0
        object.__setattr__(self, "scale_w_sr", float(scale))


@dataclass(frozen=True)
class CollimatedLight:
    """A collimated ambient source: the Sun, a solar simulator, Earth or Moon albedo.

    Attributes
    ----------
    name : str
        "sun", "solar_simulator", "earth" or "moon".
    direction : (3,) float64
        Unit propagation direction of the light (from the source towards the scene).
    irradiance_w_m2 : float
        In-band irradiance on a surface perpendicular to the beam [W/m^2].
    footprint_centre_m : (3,) float64 or None
        A point on the beam axis; with ``footprint_size_m`` the beam is a square (rectangular)
        prism around that axis and points outside it get no light.
    footprint_size_m : (float, float) or None
        Width and height of the beam cross-section [m].
    footprint_u, footprint_v : (3,) float64
        Unit vectors spanning the beam cross-section (width along u, height along v).
    """

    name: str
    direction: np.ndarray
    irradiance_w_m2: float
    footprint_centre_m: np.ndarray | None = None
    footprint_size_m: tuple[float, float] | None = None
    footprint_u: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    footprint_v: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))


def beam_cross_section_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``direction``: u horizontal-ish, v completing it.

    u is perpendicular to both the beam and world z where possible, so a square beam's edges
    stay aligned with the floor for a beam that is not vertical.
    """
    d = np.asarray(direction, dtype=np.float64)
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(ref, d)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    return u, v
