"""Ambient irradiance of the seed paper's background model (section 2.2.2, eqs. 12-14).

All functions return in-band irradiance [W/m^2] at the target on a surface facing the source.
"""

from __future__ import annotations

import numpy as np
from scipy import integrate

from sim_core.constants import (
    ASTRONOMICAL_UNIT_M,
    BOLTZMANN_J_K,
    EARTH_ALBEDO,
    EARTH_RADIUS_M,
    MOON_ALBEDO,
    MOON_RADIUS_M,
    PLANCK_J_S,
    SOLAR_RADIUS_M,
    SOLAR_TEMPERATURE_K,
    SPEED_OF_LIGHT_M_S,
)

#: first and second radiation constants, c1 = 2*pi*h*c^2 [W m^2], c2 = h*c/k [m K]
C1_W_M2 = 2.0 * np.pi * PLANCK_J_S * SPEED_OF_LIGHT_M_S**2
C2_M_K = PLANCK_J_S * SPEED_OF_LIGHT_M_S / BOLTZMANN_J_K


def planck_exitance_w_m3(wavelength_m: np.ndarray, temperature_k: float) -> np.ndarray:
    """Spectral exitance of a black body, c1 / lambda^5 / (exp(c2 / (lambda T)) - 1) [W/m^3]."""
    lam = np.asarray(wavelength_m, dtype=np.float64)
    # expm1 keeps precision where c2/(lambda T) is small; the clip keeps exp from overflowing
    # (beyond 700 the exitance is below 1e-300 of its peak anyway).
    x = np.clip(C2_M_K / (lam * temperature_k), 1e-12, 700.0)
    return C1_W_M2 / lam**5 / np.expm1(x)


def solar_in_band_irradiance_w_m2(
    band_m: tuple[float, float],
    distance_m: float = ASTRONOMICAL_UNIT_M,
    temperature_k: float = SOLAR_TEMPERATURE_K,
    solar_radius_m: float = SOLAR_RADIUS_M,
) -> float:
    """Direct solar irradiance in a wavelength band at ``distance_m`` from the Sun (eq. 12).

    E_S = integral over the band of M_lambda(T_S) * R_S^2 / R_{S-E}^2.

    >>> round(solar_in_band_irradiance_w_m2((830e-9, 870e-9)), 1)
    39.5
    """
    lo, hi = band_m
    val, _ = integrate.quad(lambda lam: float(planck_exitance_w_m3(lam, temperature_k)), lo, hi)
    return float(val * solar_radius_m**2 / distance_m**2)


def _albedo_phase_integral(theta_rad: float) -> float:
    """Closed form of the double integral in eqs. 13 and 14 (times 4/3), dimensionless."""
    t = float(theta_rad)
    return (4.0 / 3.0) * (
        np.cos(t) * (np.pi / 2.0 - t / 2.0 + np.sin(2.0 * t) / 4.0)
        + np.sin(t) * (0.25 - np.cos(2.0 * t) / 4.0)
    )


def _reflected_irradiance(
    solar_irradiance_w_m2: float, albedo: float, geometry: float, phase_angle_rad: float
) -> float:
    """Sunlight reflected by a diffuse sphere of ``albedo`` at the target (eqs. 13 and 14),
    ``geometry`` its radius squared over pi times the distance squared; never negative."""
    value = solar_irradiance_w_m2 * albedo * geometry * _albedo_phase_integral(phase_angle_rad)
    return float(max(value, 0.0))


def earth_albedo_irradiance_w_m2(
    solar_irradiance_w_m2: float,
    sun_earth_target_angle_rad: float,
    altitude_m: float,
    albedo: float = EARTH_ALBEDO,
    earth_radius_m: float = EARTH_RADIUS_M,
) -> float:
    """Irradiance of sunlight reflected by a diffuse Earth at a target in orbit (eq. 13).

    ``sun_earth_target_angle_rad`` is theta_E in [0, pi], the angle between the Sun-Earth and
    the Earth-target vectors.
    """
    geometry = earth_radius_m**2 / (np.pi * (earth_radius_m + altitude_m) ** 2)
    return _reflected_irradiance(solar_irradiance_w_m2, albedo, geometry,
                                 sun_earth_target_angle_rad)


def moon_albedo_irradiance_w_m2(
    solar_irradiance_w_m2: float,
    sun_moon_target_angle_rad: float,
    target_moon_distance_m: float,
    albedo: float = MOON_ALBEDO,
    moon_radius_m: float = MOON_RADIUS_M,
) -> float:
    """Irradiance of sunlight reflected by a diffuse Moon at the target (eq. 14)."""
    geometry = moon_radius_m**2 / (np.pi * target_moon_distance_m**2)
    return _reflected_irradiance(solar_irradiance_w_m2, albedo, geometry,
                                 sun_moon_target_angle_rad)
