"""Tests of ``Lambertian``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core.errors import InvalidInputError
from sim_core.materials import Lambertian, material_preset

from . import harness


def test_value_is_albedo_over_pi_above_the_horizon_and_zero_elsewhere() -> None:
    m = Lambertian(albedo=0.7)
    wi = harness.spherical(np.radians([0.0, 45.0, 89.99, 90.0, 120.0]), 0.3)
    wi[3, 2] = 0.0  # exactly tangent (cos(π/2) evaluates to 6e-17)
    wo = harness.repeat(harness.direction_deg(30.0), 5)
    np.testing.assert_allclose(m.eval_local(wi, wo), [0.7 / math.pi] * 3 + [0.0, 0.0])
    assert np.all(m.eval_local(wo, wi)[3:] == 0.0)


@pytest.mark.parametrize("albedo", [0.0, 0.02, 0.5, 1.0])
@pytest.mark.parametrize("theta_o", [0.0, 60.0, 89.9])
def test_directional_albedo_equals_the_parameter(albedo: float, theta_o: float) -> None:
    m = Lambertian(albedo=albedo)
    wo = harness.direction_deg(theta_o)
    assert harness.albedo_quadrature(m, wo) == pytest.approx(albedo, abs=1e-9)
    harness.check_albedo_consistency(m, wo, n_samples=10_000)


def test_every_valid_sample_has_weight_equal_to_the_albedo() -> None:
    m = Lambertian(albedo=0.37)
    rng = np.random.default_rng(0)
    s = m.sample_local(harness.repeat(harness.direction_deg(20.0), 1000), rng.random((1000, 3)))
    assert np.all(s.pdf > 0.0)
    np.testing.assert_allclose(s.weight, 0.37, rtol=1e-12)


def test_view_below_the_horizon_gives_invalid_samples() -> None:
    m = Lambertian(albedo=0.5)
    wo = harness.repeat(harness.direction_deg(100.0), 10)
    s = m.sample_local(wo, np.random.default_rng(0).random((10, 3)))
    assert np.all(s.pdf == 0.0) and np.all(s.weight == 0.0)


@pytest.mark.parametrize("theta_o", [0.0, 80.0])
def test_sampler_histogram_matches_pdf(theta_o: float) -> None:
    harness.check_chi2(Lambertian(albedo=0.5), harness.direction_deg(theta_o), seed=11)


@pytest.mark.parametrize(
    ("name", "albedo"), [("black-flannel", 0.02), ("white-diffuse", 0.9), ("grey-diffuse", 0.5)]
)
def test_presets(name: str, albedo: float) -> None:
    assert material_preset(name) == Lambertian(albedo=albedo)


@pytest.mark.parametrize("value", [-0.01, 1.01, float("nan")])
def test_out_of_range_albedo_is_rejected_with_its_value_and_range(value: float) -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        Lambertian(albedo=value)
    assert excinfo.value.field == "albedo"
    assert f"albedo = {value!r} is outside [0, 1]" in str(excinfo.value)
