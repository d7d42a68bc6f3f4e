import numpy as np
import pytest
from scipy import integrate

from sim_core.radiometry import (
    earth_albedo_irradiance_w_m2,
    moon_albedo_irradiance_w_m2,
    planck_exitance_w_m3,
    solar_in_band_irradiance_w_m2,
)


def test_whole_spectrum_gives_the_solar_constant():
    # Stefan-Boltzmann for T = 5900 K scaled by (R_S / AU)^2: about 1336 W/m^2 (1361 measured).
    e = solar_in_band_irradiance_w_m2((50e-9, 200e-6))
    sigma = 5.670374419e-8
    expected = sigma * 5900.0**4 * (6.5955e8 / 1.495978707e11) ** 2
    assert e == pytest.approx(expected, rel=2e-3)


def test_in_band_irradiance_scales_with_inverse_square_distance():
    band = (830e-9, 870e-9)
    e1 = solar_in_band_irradiance_w_m2(band)
    e2 = solar_in_band_irradiance_w_m2(band, distance_m=0.5 * 1.495978707e11)
    assert e2 == pytest.approx(4.0 * e1)


def test_planck_is_finite_at_extreme_wavelengths():
    lam = np.array([1e-9, 1e-8, 850e-9, 1e-3, 1.0])
    m = planck_exitance_w_m3(lam, 5900.0)
    assert np.all(np.isfinite(m)) and np.all(m >= 0.0)


@pytest.mark.parametrize("theta", [0.0, 0.3, 1.2, np.pi / 2, 2.5, np.pi])
def test_earth_closed_form_matches_the_double_integral_of_eq_13(theta):
    es, alt = 1000.0, 3.6e7
    pref = es * 0.35 * 6.37e6**2 / (np.pi * (6.37e6 + alt) ** 2)

    def integrand(b, lon):
        return np.cos(b) ** 3 * (np.cos(theta) * np.cos(lon) ** 2
                                 + np.sin(theta) * np.sin(lon) * np.cos(lon))

    val, _ = integrate.dblquad(integrand, theta - np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2)
    assert earth_albedo_irradiance_w_m2(es, theta, alt) == pytest.approx(
        max(pref * val, 0.0), rel=1e-6, abs=1e-12
    )


def test_full_moon_is_brighter_than_new_moon():
    full = moon_albedo_irradiance_w_m2(1000.0, 0.0, 3.84e8)
    new = moon_albedo_irradiance_w_m2(1000.0, np.pi, 3.84e8)
    assert full > 0.0 and new == pytest.approx(0.0, abs=1e-12)
