"""Concepts with one implementation: distortion inversion, sensor bounds, the suns range."""

import math

import numpy as np
import pytest
from pydantic import ValidationError

from sim_core.camera import distort_normalized, undistort_normalized, undistort_point
from sim_core.errors import InvalidInputError
from sim_core.lights import SUNS_RANGE
from sim_core.scene_spec import SensorOverrides, SolarSimulatorSpec
from sim_core.sensor import SENSOR_BOUNDS, SensorParams

K = (-0.2, 0.05, 0.001, -0.002, 0.01)


def test_array_undistortion_is_the_compiled_point_function():
    rng = np.random.default_rng(0)
    xd, yd = rng.uniform(-0.5, 0.5, (2, 3, 5))
    x, y = undistort_normalized(xd, yd, K)
    assert x.shape == y.shape == (3, 5)
    for i in np.ndindex(xd.shape):
        assert (x[i], y[i]) == undistort_point(xd[i], yd[i], *K, 20)
    rx, ry = distort_normalized(x, y, K)
    np.testing.assert_allclose(rx, xd, atol=1e-9)
    np.testing.assert_allclose(ry, yd, atol=1e-9)


@pytest.mark.parametrize("name", sorted(SENSOR_BOUNDS))
def test_spec_and_sensor_accept_the_same_range(name):
    lo, hi = SENSOR_BOUNDS[name]
    for v in (lo, hi):
        SensorOverrides(**{name: v})
        SensorParams(**{name: v})
    for v in (lo - (1 if name == "adc_bits" else max(abs(lo) * 1e-3, 1e-12)),
              hi + (1 if name == "adc_bits" else hi * 1e-3)):
        with pytest.raises(ValidationError):
            SensorOverrides(**{name: v})
        with pytest.raises(InvalidInputError):
            SensorParams(**{name: v})


def test_one_suns_range():
    import drivers.solar_simulator as solar
    from service.lab import requests

    assert solar.SUNS_RANGE is SUNS_RANGE
    assert (requests.SUNS_LOW, requests.SUNS_HIGH) == SUNS_RANGE
    for v in SUNS_RANGE:
        SolarSimulatorSpec(irradiance_suns=v, direction=[0.0, 0.0, -1.0])
    for v in (SUNS_RANGE[0] - 0.01, SUNS_RANGE[1] + 0.01, math.nan):
        with pytest.raises(ValidationError):
            SolarSimulatorSpec(irradiance_suns=v, direction=[0.0, 0.0, -1.0])
