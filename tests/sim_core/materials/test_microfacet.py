"""Tests of the shared scattering formulas (scalar kernels in ``sim_core.materials.kernels``)
and of the parameter validation in ``sim_core.materials.microfacet``.

The formulas used to be vectorised numpy helpers in ``microfacet``; the same assertions now run
on the scalar kernels, element by element (:func:`vec`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import integrate, stats

from sim_core.errors import InvalidInputError
from sim_core.materials import CookTorrance, Lambertian, material_preset
from sim_core.materials.kernels import (
    U_MAX,
    beckmann_d,
    fresnel_dielectric,
    fresnel_schlick_power,
    half_vector,
    sample_beckmann_normal,
    sample_cosine_hemisphere,
    vcavity_g,
)
from sim_core.materials.microfacet import FixedLobeMixture, check_parameter

from . import harness


def vec(kernel, *args):
    """Apply a scalar kernel to arrays (broadcast; scalars pass through) element by element.

    Returns an array (n,) for a scalar result and (n, k) for a tuple result.
    """
    arrays = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=float)) for a in args))
    return np.array([kernel(*(float(a[i]) for a in arrays)) for i in range(arrays[0].size)])


def d_of(h: np.ndarray, alpha: float) -> np.ndarray:
    """``beckmann_d`` over the rows of ``h`` (n, 3)."""
    return vec(beckmann_d, h[:, 0], h[:, 1], h[:, 2], alpha)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


@pytest.mark.parametrize("alpha", [1e-3, 0.05, 0.3, 1.0, math.sqrt(2.0)])
def test_beckmann_d_is_normalised_in_projected_area(alpha: float) -> None:
    def integrand(theta: float) -> float:
        h = harness.spherical(theta)
        return float(d_of(h, alpha)[0]) * math.cos(theta) * math.sin(theta) * 2 * math.pi

    # Split where the lobe lives so that adaptive quadrature cannot step over it.
    edges = sorted({0.0, *(min(k * alpha, 0.5 * math.pi) for k in (1, 3, 10)), 0.5 * math.pi})
    total = sum(integrate.quad(integrand, a, b, limit=200)[0] for a, b in itertools.pairwise(edges))
    assert total == pytest.approx(1.0, abs=1e-7)


def test_beckmann_d_is_finite_and_zero_at_and_below_the_horizon() -> None:
    h = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, -1e-9], [0.0, 0.0, -1.0], [1.0, 0.0, 1e-300]])
    for alpha in (1e-6, 1.0, math.sqrt(2.0)):
        d = d_of(h, alpha)
        assert np.all(np.isfinite(d))
        assert np.all(d == 0.0)


def test_beckmann_d_peak_is_one_over_pi_alpha_squared() -> None:
    z = np.array([[0.0, 0.0, 1.0]])
    for alpha in (1e-6, 0.2, 1.0):
        assert d_of(z, alpha)[0] == pytest.approx(1.0 / (math.pi * alpha**2), rel=1e-12)


@pytest.mark.parametrize("alpha", [0.01, 0.3, 1.2])
def test_beckmann_sampling_follows_the_analytic_slope_cdf(alpha: float) -> None:
    # With h ~ D(h) cos θh, tan²θh / α² is exponentially distributed with mean 1.
    rng = np.random.default_rng(1)
    u = rng.random((20_000, 2))
    h = vec(sample_beckmann_normal, u[:, 0], u[:, 1], alpha)
    np.testing.assert_allclose(np.linalg.norm(h, axis=1), 1.0, atol=1e-12)
    t2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / h[:, 2] ** 2
    assert stats.kstest(t2 / alpha**2, "expon").pvalue > 1e-3
    phi = np.mod(np.arctan2(h[:, 1], h[:, 0]), 2 * np.pi) / (2 * np.pi)
    assert stats.kstest(phi, "uniform").pvalue > 1e-3


def test_beckmann_sampling_is_finite_for_extreme_uniforms() -> None:
    u = np.array([0.0, U_MAX, 1.0])
    for alpha in (1e-6, math.sqrt(2.0)):
        h = vec(sample_beckmann_normal, u, u, alpha)
        assert np.all(np.isfinite(h))
        assert np.all(h[:, 2] >= 0.0)


def test_cosine_hemisphere_samples_have_uniform_cos_squared() -> None:
    rng = np.random.default_rng(2)
    u = rng.random((20_000, 2))
    w = vec(sample_cosine_hemisphere, u[:, 0], u[:, 1])
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12)
    assert np.all(w[:, 2] > 0.0)
    assert stats.kstest(w[:, 2] ** 2, "uniform").pvalue > 1e-3


def test_cosine_hemisphere_sample_stays_above_horizon_for_u_at_one() -> None:
    w = vec(sample_cosine_hemisphere, np.array([1.0, U_MAX]), np.array([0.3, 0.3]))
    assert np.all(w[:, 2] > 0.0)


def _fresnel_reference(theta_i: float, n2: float) -> float:
    """Textbook form via the refraction angle: rs = sin²(θi-θt)/sin²(θi+θt), rp = tan²/tan²."""
    if theta_i == 0.0:
        return ((n2 - 1.0) / (n2 + 1.0)) ** 2
    theta_t = math.asin(math.sin(theta_i) / n2)
    rs = (math.sin(theta_i - theta_t) / math.sin(theta_i + theta_t)) ** 2
    rp = (math.tan(theta_i - theta_t) / math.tan(theta_i + theta_t)) ** 2
    return 0.5 * (rs + rp)


@pytest.mark.parametrize("n2", [1.2, 1.46, 2.26, 3.0])
@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 45.0, 60.0, 80.0, 89.0])
def test_fresnel_dielectric_matches_the_refraction_angle_form(n2: float, theta_deg: float) -> None:
    theta = math.radians(theta_deg)
    got = fresnel_dielectric(math.cos(theta), n2)
    assert got == pytest.approx(_fresnel_reference(theta, n2), rel=1e-10)


def test_fresnel_dielectric_limits() -> None:
    c = np.array([0.0, 1e-300, 0.5, 1.0])
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)
    np.testing.assert_array_equal(vec(fresnel_dielectric, c, 1.0), 0.0)  # index-matched
    for n2 in (1.0, 1.0 + 1e-12, 3.0):
        f = vec(fresnel_dielectric, np.array([-0.5, 0.0, 1e-300, 0.3, 1.0, 1.0 + 1e-15]), n2)
        assert np.all(np.isfinite(f))
        assert np.all((f >= 0.0) & (f <= 1.0))


def test_brewster_angle_leaves_only_s_polarisation() -> None:
    n2 = 1.5
    theta_b = math.atan(n2)
    theta_t = 0.5 * math.pi - theta_b
    rs = (math.sin(theta_b - theta_t) / math.sin(theta_b + theta_t)) ** 2
    assert fresnel_dielectric(math.cos(theta_b), n2) == pytest.approx(rs / 2)


def test_schlick_power_fresnel_endpoints_and_schlick_case() -> None:
    c = np.array([1.0, 0.0, 0.5])
    np.testing.assert_allclose(
        vec(fresnel_schlick_power, c, 0.04, 5.0), [0.04, 1.0, 0.04 + 0.96 / 32]
    )
    np.testing.assert_array_equal(vec(fresnel_schlick_power, c, 0.3, 0.0), 1.0)  # n = 0: F = 1
    f = vec(fresnel_schlick_power, np.array([-0.2, 1.2, 0.0]), 0.0, 100.0)
    assert np.all(np.isfinite(f)) and np.all((f >= 0) & (f <= 1))


def test_vcavity_g_is_symmetric_bounded_and_one_at_normal_incidence() -> None:
    rng = np.random.default_rng(3)
    wi = harness.spherical(rng.uniform(0, 0.5 * np.pi, 500), rng.uniform(0, 2 * np.pi, 500))
    wo = harness.spherical(rng.uniform(0, 0.5 * np.pi, 500), rng.uniform(0, 2 * np.pi, 500))
    h = vec(half_vector, *wi.T, *wo.T)
    g1 = vec(vcavity_g, h[:, 2], wi[:, 2], wo[:, 2], dot(wi, h))
    g2 = vec(vcavity_g, h[:, 2], wo[:, 2], wi[:, 2], dot(wo, h))
    np.testing.assert_allclose(g1, g2, rtol=1e-12)
    assert np.all((g1 >= 0.0) & (g1 <= 1.0))
    assert vcavity_g(1.0, 1.0, 1.0, 1.0) == 1.0
    assert np.isfinite(vcavity_g(0.0, 0.0, 0.0, 0.0))


def test_half_vector_of_opposite_directions_is_finite() -> None:
    wi = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])
    h = vec(half_vector, *wi.T, *(-wi).T)
    assert np.all(np.isfinite(h))
    np.testing.assert_allclose(np.linalg.norm(h, axis=1), 1.0)


@pytest.mark.parametrize(
    ("value", "fragment"),
    [
        (1.3, "ks = 1.3 is outside [0, 1]"),
        (-0.1, "ks = -0.1 is outside [0, 1]"),
        (float("nan"), "ks = nan is outside [0, 1]"),
        (float("inf"), "ks = inf is outside [0, 1]"),
        ("0.5", "ks = '0.5' is not a real number; allowed range [0, 1]"),
        (True, "ks = True is not a real number"),
        (None, "ks = None is not a real number"),
    ],
)
def test_check_parameter_names_parameter_value_and_range(value: object, fragment: str) -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        check_parameter("ks", value, 0.0, 1.0, model="test-model")
    assert excinfo.value.field == "ks"
    assert fragment in str(excinfo.value)
    assert "test-model" in str(excinfo.value)


def test_check_parameter_accepts_bounds_and_numpy_scalars() -> None:
    assert check_parameter("x", 0, 0.0, 1.0, model="m") == 0.0
    assert check_parameter("x", np.float32(1.0), 0.0, 1.0, model="m") == 1.0
    assert isinstance(check_parameter("x", np.int64(1), 0.0, 2.0, model="m"), float)


# -------------------------------------------------------------------------------------------
# The fixed-lobe reference sampler (issue 16)
# -------------------------------------------------------------------------------------------
def test_fixed_lobe_mixture_has_the_brdf_of_its_base_and_a_consistent_sampler() -> None:
    tile = material_preset("black-glossy-tile")
    naive = FixedLobeMixture(tile)
    wi = harness.spherical(np.radians([5.0, 40.0, 70.0]), 0.0)
    wo = harness.spherical(np.radians(40.0), np.pi)
    wo = np.repeat(wo, 3, axis=0)
    np.testing.assert_array_equal(naive.eval_local(wi, wo), tile.eval_local(wi, wo))
    assert naive.kernel_kind == tile.kernel_kind and naive.albedo_bound == tile.albedo_bound
    # half the samples in each lobe, whatever the Fresnel factor: the pdf says so
    cos_i = wi[:, 2]
    beckmann = CookTorrance(kd=0.0, ks=0.25, m=0.06, n2=1.46).pdf_local(wi, wo)
    np.testing.assert_allclose(naive.pdf_local(wi, wo), 0.5 * beckmann + 0.5 * cos_i / math.pi,
                               rtol=1e-12)
    harness.check_chi2(naive, harness.direction_deg(40.0, 75.0), seed=11)
    harness.check_albedo_consistency(naive, harness.direction_deg(40.0, 75.0),
                                     n_samples=100_000, seed=12)


def test_fixed_lobe_mixture_refuses_a_model_without_lobes_and_a_starved_lobe() -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        FixedLobeMixture(Lambertian(0.5))  # type: ignore[arg-type]
    assert excinfo.value.field == "base"
    with pytest.raises(InvalidInputError, match=r"p_spec = 0.01 is outside \[0.05, 1\]"):
        FixedLobeMixture(material_preset("black-glossy-tile"), p_spec=0.01)
    with pytest.raises(InvalidInputError, match=r"p_spec = 1\.0 is outside"):
        FixedLobeMixture(material_preset("black-glossy-tile"), p_spec=1.0)
