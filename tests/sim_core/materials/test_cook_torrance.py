"""Tests of ``CookTorrance`` (NLOS relay-wall paper eqs. (3)-(12), Table 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core.errors import InvalidInputError
from sim_core.materials import CookTorrance, material_preset
from sim_core.materials.kernels import fresnel_dielectric, lobe_probabilities

from . import harness


def fresnel_eq_11_12(theta: float, n2: float, n1: float = 1.0) -> float:
    root = math.sqrt(1 - (n1 / n2 * math.sin(theta)) ** 2)
    rs = ((n1 * math.cos(theta) - n2 * root) / (n1 * math.cos(theta) + n2 * root)) ** 2
    rp = ((n1 * root - n2 * math.cos(theta)) / (n1 * root + n2 * math.cos(theta))) ** 2
    return (rs + rp) / 2


def reference_value(
    theta_i: float,
    theta_r: float,
    dphi: float,
    kd: float,
    ks: float,
    m: float,
    n2: float,
    fresnel_angle: str,
) -> float:
    """Eqs. (3), (4), (5), (8)-(12) in scalar math, angles in degrees."""
    ti, tr, dp = (math.radians(x) for x in (theta_i, theta_r, dphi))
    cos_o = math.sqrt(  # eq. (3): angle between the light and the microfacet normal
        (math.cos(ti) * math.cos(tr) + math.sin(ti) * math.sin(tr) * math.cos(dp) + 1) / 2
    )
    cos_a = (math.cos(ti) + math.cos(tr)) / (2 * cos_o)  # eq. (4)
    x = (1 - cos_a**2) / cos_a**2  # tan²α
    p = math.exp(-x / m**2) / (math.pi * m**2)  # eq. (9), slope pdf
    d = p / cos_a**4  # eq. (5)
    g = min(1.0, 2 * cos_a * math.cos(tr) / cos_o, 2 * cos_a * math.cos(ti) / cos_o)  # (10)
    theta_f = ti if fresnel_angle == "incidence" else math.acos(cos_o)
    f = fresnel_eq_11_12(theta_f, n2)
    return kd / math.pi + ks * d * g * f / (4 * math.cos(ti) * math.cos(tr))  # eq. (8)


@pytest.mark.parametrize(
    ("theta_i", "theta_r", "dphi"),
    [(40, 40, 180), (30, 50, 180), (50, 20, 180), (40, 60, 120), (20, 70, 30), (85, 80, 180)],
)
@pytest.mark.parametrize("fresnel_angle", ["incidence", "half"])
@pytest.mark.parametrize(
    "params",
    [
        {"kd": 0.05, "ks": 0.90, "m": 0.08, "n2": 1.60},  # the paper's Fig. 10 base set
        {"kd": 0.3, "ks": 0.6, "m": 0.5, "n2": 2.9},
    ],
)
def test_value_matches_paper_equations(
    theta_i: float, theta_r: float, dphi: float, fresnel_angle: str, params: dict[str, float]
) -> None:
    mat = CookTorrance(**params, fresnel_angle=fresnel_angle)
    wi = harness.spherical(math.radians(theta_i), 0.0)
    wo = harness.spherical(math.radians(theta_r), math.radians(dphi))
    expected = reference_value(theta_i, theta_r, dphi, **params, fresnel_angle=fresnel_angle)
    assert mat.eval_local(wi, wo)[0] == pytest.approx(expected, rel=1e-9)


def test_normal_distribution_carries_the_cos4_normalisation() -> None:
    # Off-specular (half vector 40° from the normal) the 1/cos⁴α factor of eq. (5) must be
    # present: eq. (9) alone would give a value cos⁴40° ≈ 0.34 times as large.
    m, ks = 0.5, 1.0
    mat = CookTorrance(kd=0.0, ks=ks, m=m, n2=1.5, fresnel_angle="half")
    wi = harness.spherical(math.radians(10.0), 0.0)
    wo = harness.spherical(math.radians(70.0), 0.0)  # same side: half vector 40° off the normal
    h = (wi + wo) / np.linalg.norm(wi + wo)
    cos_a = h[0, 2]
    cos_o = float(wi[0] @ h[0])
    g = min(
        1.0,
        2 * cos_a * math.cos(math.radians(10.0)) / cos_o,
        2 * cos_a * math.cos(math.radians(70.0)) / cos_o,
    )
    slope_pdf = math.exp(-(1 - cos_a**2) / cos_a**2 / m**2) / (math.pi * m**2)
    common = (
        ks
        * g
        * fresnel_eq_11_12(math.acos(cos_o), 1.5)
        / (4 * math.cos(math.radians(10.0)) * math.cos(math.radians(70.0)))
    )
    assert mat.eval_local(wi, wo)[0] == pytest.approx(common * slope_pdf / cos_a**4, rel=1e-9)
    assert mat.eval_local(wi, wo)[0] != pytest.approx(common * slope_pdf, rel=0.1)


def test_incidence_fresnel_is_not_reciprocal_and_half_fresnel_is() -> None:
    wi = harness.spherical(math.radians(20.0), 0.0)
    wo = harness.spherical(math.radians(60.0), math.radians(180.0))
    paper = CookTorrance(kd=0.0, ks=0.9, m=0.3, n2=2.26, fresnel_angle="incidence")
    half = CookTorrance(kd=0.0, ks=0.9, m=0.3, n2=2.26, fresnel_angle="half")
    forward, backward = paper.eval_local(wi, wo)[0], paper.eval_local(wo, wi)[0]
    # The ratio is exactly F(20°)/F(60°): only the Fresnel factor breaks the symmetry.
    ratio = fresnel_eq_11_12(math.radians(20.0), 2.26) / fresnel_eq_11_12(math.radians(60), 2.26)
    assert forward / backward == pytest.approx(ratio, rel=1e-9)
    assert abs(forward / backward - 1.0) > 0.05
    assert half.eval_local(wi, wo)[0] == pytest.approx(half.eval_local(wo, wi)[0], rel=1e-12)


def test_default_fresnel_angle_is_the_papers_incidence_angle() -> None:
    assert CookTorrance().fresnel_angle == "incidence"


def test_defaults_are_the_papers_figure_10_base_set() -> None:
    assert CookTorrance() == CookTorrance(kd=0.05, ks=0.90, m=0.08, n2=1.60)


@pytest.mark.parametrize(
    ("name", "kd", "ks", "m", "n2"),
    [
        ("black-protective-shield", 0.00, 0.79, 0.15, 2.26),
        ("white-matte-tile", 0.78, 0.20, 0.08, 1.67),
        ("black-glossy-tile", 0.07, 0.25, 0.06, 1.46),
    ],
)
def test_presets_carry_the_table_2_averages(
    name: str, kd: float, ks: float, m: float, n2: float
) -> None:
    assert material_preset(name) == CookTorrance(kd=kd, ks=ks, m=m, n2=n2)


def test_index_matched_surface_reflects_only_diffusely() -> None:
    mat = CookTorrance(kd=0.4, ks=0.6, m=0.2, n2=1.0)
    wi = harness.spherical(np.radians([0.0, 30.0, 89.0]), 0.0)
    wo = harness.spherical(np.radians([0.0, 30.0, 89.0]), np.pi)
    np.testing.assert_allclose(mat.eval_local(wi, wo), 0.4 / math.pi, rtol=1e-12)


def test_the_glossy_tile_samples_its_dim_specular_lobe_in_proportion_to_its_albedo() -> None:
    # Normal view: F = ((n2 - 1) / (n2 + 1))^2 = 0.035, so the lobe reflects ks F = 0.0087
    # against kd = 0.07 and gets 11 % of the samples (ks / (ks + kd) would give it 78 %).
    tile = material_preset("black-glossy-tile")
    f0 = ((1.46 - 1.0) / (1.46 + 1.0)) ** 2
    p_spec, p_diff = lobe_probabilities(tile.kernel_kind, tile.kernel_params(), 1.0)
    assert p_spec == pytest.approx(0.25 * f0 / (0.25 * f0 + 0.07), rel=1e-12)
    assert p_spec == pytest.approx(0.111, abs=1e-3)
    assert p_diff == pytest.approx(1.0 - p_spec, rel=1e-12)
    # At grazing view the lobe reflects more (F -> 1) and gets more of the samples.
    grazing, _ = lobe_probabilities(tile.kernel_kind, tile.kernel_params(), math.cos(1.5))
    assert grazing > 0.5
    # Measured: the lobe's albedo (quadrature) agrees with ks F(θo) within 8 % up to 70°.
    spec = CookTorrance(kd=0.0, ks=0.25, m=0.06, n2=1.46)
    for theta in (0.0, 40.0, 70.0):
        wo = harness.direction_deg(theta)
        a_spec = harness.albedo_quadrature(spec, wo)
        estimate = 0.25 * fresnel_dielectric(math.cos(math.radians(theta)), 1.46)
        assert estimate == pytest.approx(a_spec, rel=0.08)


MATERIALS = [
    material_preset("black-protective-shield"),
    material_preset("white-matte-tile"),
    material_preset("black-glossy-tile"),
    CookTorrance(kd=0.2, ks=0.8, m=0.6, n2=3.0, fresnel_angle="half"),
    CookTorrance(kd=0.0, ks=1.0, m=1.0, n2=3.0, fresnel_angle="incidence"),
]


@pytest.mark.parametrize("material", MATERIALS, ids=repr)
@pytest.mark.parametrize("theta_o", [0.0, 40.0, 80.0])
def test_sampling_estimate_of_albedo_matches_quadrature(
    material: CookTorrance, theta_o: float
) -> None:
    harness.check_albedo_consistency(material, harness.direction_deg(theta_o, 75.0),
                                     n_samples=100_000, seed=3)


@pytest.mark.parametrize("material", MATERIALS, ids=repr)
@pytest.mark.parametrize("theta_o", [25.0, 70.0])
def test_sampler_histogram_matches_pdf(material: CookTorrance, theta_o: float) -> None:
    harness.check_chi2(material, harness.direction_deg(theta_o, 75.0), seed=7)


@pytest.mark.parametrize("fresnel_angle", ["incidence", "half"])
def test_albedo_of_the_most_reflective_parameters_stays_below_one(fresnel_angle: str) -> None:
    wos = np.stack([harness.direction_deg(t) for t in (0.0, 45.0, 75.0, 89.0, 89.99)])
    for m in (1e-6, 0.05, 0.5, 1.0):
        mat = CookTorrance(kd=0.0, ks=1.0, m=m, n2=3.0, fresnel_angle=fresnel_angle)
        harness.check_albedo_at_most_one(mat, wos, n_samples=50_000)


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("kd", -0.2, "[0, 1]"),
        ("ks", 1.3, "[0, 1]"),
        ("m", 0.0, "[1e-06, 1]"),
        ("m", 1.1, "[1e-06, 1]"),
        ("n2", 0.9, "[1, 3]"),
        ("n2", 3.5, "[1, 3]"),
    ],
)
def test_out_of_range_parameter_is_rejected_with_its_name_value_and_range(
    field: str, value: float, allowed: str
) -> None:
    harness.check_out_of_range_rejected(CookTorrance, {"kd": 0.0, "ks": 0.0}, field, value, allowed)


def test_kd_plus_ks_above_one_is_rejected() -> None:
    with pytest.raises(InvalidInputError, match=r"kd \+ ks = 0.8 \+ 0.3 = 1.1 exceeds 1"):
        CookTorrance(kd=0.8, ks=0.3)
    CookTorrance(kd=0.78, ks=0.22)


def test_unknown_fresnel_angle_is_rejected_listing_the_choices() -> None:
    with pytest.raises(InvalidInputError, match="'incidence', 'half'") as excinfo:
        CookTorrance(fresnel_angle="reflection")  # type: ignore[arg-type]
    assert excinfo.value.field == "fresnel_angle"
