"""Tests of ``SeedMicrofacet`` (seed paper eqs. (9)-(10), Table 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core.errors import InvalidInputError
from sim_core.materials import SeedMicrofacet, material_preset

from . import harness


def reference_value(
    theta_i: float,
    theta_r: float,
    dphi: float,
    ks: float,
    kd: float,
    n: float,
    sigma: float,
    f0: float,
) -> float:
    """Eqs. (9)-(10) in scalar math, angles in degrees; half-angle relations from harness.spherical
    trigonometry (cos γ = sqrt((1 + wi·wo)/2), cos θh = (cos θi + cos θr) / (2 cos γ))."""
    ti, tr, dp = (math.radians(x) for x in (theta_i, theta_r, dphi))
    cos_gamma = math.sqrt(
        (math.cos(ti) * math.cos(tr) + math.sin(ti) * math.sin(tr) * math.cos(dp) + 1) / 2
    )
    cos_h = (math.cos(ti) + math.cos(tr)) / (2 * cos_gamma)
    alpha = math.sqrt(2 * sigma)
    tan2 = (1 - cos_h**2) / cos_h**2
    d = math.exp(-tan2 / alpha**2) / (math.pi * alpha**2 * cos_h**4)
    f = f0 + (1 - f0) * (1 - cos_gamma) ** n
    g = min(1.0, 2 * cos_h * math.cos(tr) / cos_gamma, 2 * cos_h * math.cos(ti) / cos_gamma)
    return ks / (4 * math.cos(ti) * math.cos(tr)) * d * f * g + kd / math.pi


@pytest.mark.parametrize(
    ("theta_i", "theta_r", "dphi"),
    [(30, 30, 180), (30, 40, 180), (40, 20, 150), (60, 70, 90), (10, 80, 0), (85, 85, 180)],
)
@pytest.mark.parametrize(
    "params",
    [
        {"ks": 0.649, "kd": 0.081, "n": 8.51, "sigma": 0.014, "f0": 0.775},
        {"ks": 0.5, "kd": 0.3, "n": 2.0, "sigma": 0.4, "f0": 0.1},
    ],
)
def test_value_matches_paper_equations_9_and_10(
    theta_i: float, theta_r: float, dphi: float, params: dict[str, float]
) -> None:
    m = SeedMicrofacet(
        ks=params["ks"],
        kd=params["kd"],
        fresnel_exponent=params["n"],
        sigma=params["sigma"],
        f0=params["f0"],
    )
    wi = harness.spherical(math.radians(theta_i), 0.0)
    wo = harness.spherical(math.radians(theta_r), math.radians(dphi))
    expected = reference_value(theta_i, theta_r, dphi, **params)
    assert m.eval_local(wi, wo)[0] == pytest.approx(expected, rel=1e-9)


def test_width_follows_the_printed_relation_alpha_sqrt_2_sigma() -> None:
    # Normal incidence and view: h = n, D = 1/(π α²), G = 1, F = F0.
    sigma, ks, f0 = 0.014, 0.6, 0.775
    m = SeedMicrofacet(ks=ks, kd=0.0, sigma=sigma, f0=f0)
    z = np.array([[0.0, 0.0, 1.0]])
    printed = ks * f0 / (4 * math.pi * 2 * sigma)  # α² = 2σ
    standard = ks * f0 / (4 * math.pi * 2 * sigma**2)  # α² = 2σ² would be 71x larger
    assert m.alpha == pytest.approx(math.sqrt(2 * sigma))
    assert m.eval_local(z, z)[0] == pytest.approx(printed, rel=1e-12)
    assert m.eval_local(z, z)[0] != pytest.approx(standard, rel=0.5)


def test_presets_carry_table_1_values() -> None:
    film = material_preset("thermal-control-film")
    cell = material_preset("silicon-solar-cell")
    assert film == SeedMicrofacet(ks=0.649, kd=0.081, fresnel_exponent=8.51, sigma=0.014, f0=0.775)
    assert cell == SeedMicrofacet(ks=0.350, kd=0.053, fresnel_exponent=2.22, sigma=0.010, f0=0.021)


def test_defaults_are_the_thermal_control_film() -> None:
    assert SeedMicrofacet() == material_preset("thermal-control-film")


MATERIALS = [
    material_preset("thermal-control-film"),
    material_preset("silicon-solar-cell"),
    SeedMicrofacet(ks=0.6, kd=0.3, fresnel_exponent=5.0, sigma=0.3, f0=0.5),
    SeedMicrofacet(ks=1.0, kd=0.0, fresnel_exponent=0.0, sigma=1.0, f0=1.0),
]


@pytest.mark.parametrize("material", MATERIALS, ids=repr)
@pytest.mark.parametrize("theta_o", [0.0, 35.0, 70.0, 85.0])
def test_sampling_estimate_of_albedo_matches_quadrature(
    material: SeedMicrofacet, theta_o: float
) -> None:
    harness.check_albedo_consistency(material, harness.direction_deg(theta_o, 30.0),
                                     n_samples=100_000)


@pytest.mark.parametrize("material", MATERIALS, ids=repr)
@pytest.mark.parametrize("theta_o", [10.0, 60.0, 85.0])
def test_sampler_histogram_matches_pdf(material: SeedMicrofacet, theta_o: float) -> None:
    harness.check_chi2(material, harness.direction_deg(theta_o, 30.0), seed=int(theta_o))


def test_albedo_of_the_most_reflective_parameters_stays_below_one() -> None:
    # ks = 1, F = 1: everything the V-cavity lets out is reflected; worst case for energy.
    wos = np.stack([harness.direction_deg(t) for t in (0.0, 45.0, 75.0, 89.0, 89.99)])
    for sigma in (1e-6, 0.01, 0.3, 1.0):
        m = SeedMicrofacet(ks=1.0, kd=0.0, fresnel_exponent=0.0, sigma=sigma, f0=1.0)
        harness.check_albedo_at_most_one(m, wos, n_samples=50_000)


def test_lobe_choice_follows_ks_and_kd() -> None:
    rng = np.random.default_rng(5)
    wo = harness.repeat(harness.direction_deg(30.0), 4000)
    u = rng.random((4000, 3))
    diffuse_only = SeedMicrofacet(ks=0.0, kd=0.7)
    s = diffuse_only.sample_local(wo, u)
    np.testing.assert_allclose(s.pdf, s.wi[:, 2] / math.pi, rtol=1e-12)
    specular_only = SeedMicrofacet(ks=0.7, kd=0.0, sigma=1e-4)
    s = specular_only.sample_local(wo, u)
    # α = 0.014: every specular sample lies within a few degrees of the mirror direction.
    mirror = np.array([-wo[0, 0], -wo[0, 1], wo[0, 2]])
    assert np.mean(s.wi @ mirror > math.cos(math.radians(10.0))) > 0.99


def test_black_body_reflects_nothing() -> None:
    m = SeedMicrofacet(ks=0.0, kd=0.0)
    wo = harness.repeat(harness.direction_deg(40.0), 100)
    s = m.sample_local(wo, np.random.default_rng(0).random((100, 3)))
    assert np.all(s.weight == 0.0)
    assert np.all(m.eval_local(s.wi, wo) == 0.0)


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("ks", 1.3, "[0, 1]"),
        ("ks", -0.1, "[0, 1]"),
        ("kd", 1.5, "[0, 1]"),
        ("fresnel_exponent", -1.0, "[0, 100]"),
        ("fresnel_exponent", 101.0, "[0, 100]"),
        ("sigma", 0.0, "[1e-06, 1]"),
        ("sigma", 1.5, "[1e-06, 1]"),
        ("f0", -0.01, "[0, 1]"),
        ("f0", 1.01, "[0, 1]"),
    ],
)
def test_out_of_range_parameter_is_rejected_with_its_name_value_and_range(
    field: str, value: float, allowed: str
) -> None:
    harness.check_out_of_range_rejected(SeedMicrofacet, {"ks": 0.0, "kd": 0.0}, field, value,
                                        allowed)


def test_ks_plus_kd_above_one_is_rejected() -> None:
    with pytest.raises(InvalidInputError, match=r"ks \+ kd = 0.7 \+ 0.5 = 1.2 exceeds 1"):
        SeedMicrofacet(ks=0.7, kd=0.5)
    SeedMicrofacet(ks=0.7, kd=0.3)  # exactly 1 (with decimal rounding) is allowed


def test_tiny_diffuse_lobe_next_to_full_specular_keeps_a_positive_density() -> None:
    # p_diff = kd / (ks + kd) is not computed as 1 - p_spec, which would round to 0 here.
    m = SeedMicrofacet(ks=1.0 - 1e-250, kd=1e-250, sigma=1e-6)
    wi = harness.spherical(np.radians([10.0, 60.0]), 0.0)
    wo = harness.spherical(np.radians([50.0, 20.0]), 1.0)
    assert np.all(m.eval_local(wi, wo) > 0.0)
    assert np.all(m.pdf_local(wi, wo) > 0.0)
