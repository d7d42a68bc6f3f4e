"""Property tests over parameters and directions for every material model.

Directions include the edge cases named in the contract: normal, grazing (89.99°), within
1e-12 and 1e-300 of the horizon, exactly tangent, below the horizon, coincident ``wi == wo``,
mirror pairs and opposite pairs; parameters include their bounds.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sim_core.materials import CookTorrance, Hapke, Lambertian, Material, SeedMicrofacet
from sim_core.materials import kernels as kn
from sim_core.materials.hapke import hapke_max_w
from sim_core.materials.microfacet import U_MAX

from .harness import check_albedo_at_most_one

FAST = settings(max_examples=40, deadline=None)
SLOW = settings(max_examples=15, deadline=None)


# -------------------------------------------------------------------------------------------
# Strategies
# -------------------------------------------------------------------------------------------
def bounded(lo: float, hi: float, *specials: float) -> st.SearchStrategy[float]:
    """Floats in [lo, hi], with the bounds and ``specials`` drawn often."""
    return st.one_of(st.sampled_from([lo, hi, *specials]), st.floats(lo, hi))


@st.composite
def _lobe_weights(draw: st.DrawFn, both_lobes: bool) -> tuple[float, float]:
    """(ks, kd) with ks + kd <= 1; with ``both_lobes`` both strictly positive (drawn so, not
    filtered: a filter on ks > 0 and kd > 0 would throw most draws away)."""
    if not both_lobes:
        ks = draw(bounded(0.0, 1.0))
        kd = draw(st.one_of(st.sampled_from([0.0, 1.0 - ks]), st.floats(0.0, 1.0 - ks)))
        return ks, kd
    ks = draw(bounded(1e-300, 1.0 - 1e-9, 0.5))
    kd = draw(st.one_of(st.sampled_from([1.0 - ks, 5e-324]),
                        st.floats(0.0, 1.0 - ks, exclude_min=True)))
    return ks, kd


@st.composite
def seed_microfacets(draw: st.DrawFn, both_lobes: bool = False) -> SeedMicrofacet:
    ks, kd = draw(_lobe_weights(both_lobes))
    return SeedMicrofacet(
        ks=ks,
        kd=kd,
        fresnel_exponent=draw(bounded(0.0, 100.0, 5.0)),
        sigma=draw(bounded(1e-6, 1.0, 0.014)),
        f0=draw(bounded(0.0, 1.0)),
    )


@st.composite
def cook_torrances(
    draw: st.DrawFn, fresnel_angle: str | None = None, both_lobes: bool = False
) -> CookTorrance:
    ks, kd = draw(_lobe_weights(both_lobes))
    angle = fresnel_angle or draw(st.sampled_from(["incidence", "half"]))
    return CookTorrance(
        kd=kd, ks=ks, m=draw(bounded(1e-6, 1.0)), n2=draw(bounded(1.0, 3.0)), fresnel_angle=angle
    )


def lambertians() -> st.SearchStrategy[Lambertian]:
    return st.builds(Lambertian, albedo=bounded(0.0, 1.0))


#: (b0, h, phase_b) combinations whose largest allowed w is precomputed
_HAPKE_CORNERS = [(2.0, 1.0, 1.0), (2.0, 1.0, -1.0), (0.0, 0.0, 0.0), (2.0, 0.01, 1.0)]


@functools.cache
def _w_max(b0: float, h: float, b: float) -> float:
    return hapke_max_w(b0, h, b)


@st.composite
def hapkes(draw: st.DrawFn) -> Hapke:
    if draw(st.booleans()):
        # At the energy limit of a worst-case corner.
        b0, h, b = draw(st.sampled_from(_HAPKE_CORNERS))
        return Hapke(w=_w_max(b0, h, b), b0=b0, h=h, phase_b=b)
    # Anywhere in the box where every w <= 0.78 is allowed.
    return Hapke(
        w=draw(bounded(0.0, 0.78)),
        b0=draw(bounded(0.0, 2.0)),
        h=draw(bounded(0.0, 1.0)),
        phase_b=draw(bounded(-1.0, 1.0)),
    )


def materials() -> st.SearchStrategy[Material]:
    return st.one_of(seed_microfacets(), cook_torrances(), lambertians(), hapkes())


def reciprocal_materials() -> st.SearchStrategy[Material]:
    return st.one_of(seed_microfacets(), cook_torrances("half"), lambertians(), hapkes())


#: cosines of special polar angles: normal, 45°, 89.99°, 1e-12 and 1e-300 above the horizon,
#: exactly tangent
SPECIAL_Z = [1.0, math.sqrt(0.5), math.cos(math.radians(89.99)), 1e-12, 1e-300, 0.0]


def _unit(z: float, phi: float) -> tuple[float, float, float]:
    s = math.sqrt(max(0.0, 1.0 - z * z))
    return (s * math.cos(phi), s * math.sin(phi), z)


@st.composite
def directions(draw: st.DrawFn, below: bool = False) -> tuple[float, float, float]:
    z = draw(st.one_of(st.sampled_from(SPECIAL_Z), st.floats(0.0, 1.0)))
    if below and draw(st.booleans()):
        z = -z
    return _unit(z, draw(st.floats(0.0, 2.0 * math.pi)))


@st.composite
def direction_pairs(draw: st.DrawFn, below: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Arrays (n, 3) of ``wi`` and ``wo``, with coincident, mirror and opposite pairs mixed in."""
    n = draw(st.integers(1, 12))
    wi, wo = [], []
    for _ in range(n):
        a = draw(directions(below))
        relation = draw(st.sampled_from(["free", "same", "mirror", "opposite"]))
        if relation == "free":
            b = draw(directions(below))
        elif relation == "same":
            b = a
        elif relation == "mirror":
            b = (-a[0], -a[1], a[2])
        else:
            b = (-a[0], -a[1], -a[2])
        wi.append(a)
        wo.append(b)
    return np.array(wi, dtype=float), np.array(wo, dtype=float)


def uniforms(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform numbers with the extreme values 0 and the largest float below 1 mixed in."""
    u = rng.random((n, 3))
    u[: min(n, 4)] = [[0.0, 0.0, 0.0], [U_MAX, U_MAX, U_MAX], [0.0, U_MAX, 0.5], [U_MAX, 0.0, 0.5]][
        : min(n, 4)
    ]
    return u


# -------------------------------------------------------------------------------------------
# Properties
# -------------------------------------------------------------------------------------------
@FAST
@given(material=materials(), pair=direction_pairs(below=True))
def test_brdf_and_pdf_are_finite_nonnegative_and_zero_below_the_horizon(
    material: Material, pair: tuple[np.ndarray, np.ndarray]
) -> None:
    wi, wo = pair
    f = material.eval_local(wi, wo)
    pdf = material.pdf_local(wi, wo)
    assert f.shape == pdf.shape == (len(wi),)
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0.0)
    outside = (wi[:, 2] <= 0.0) | (wo[:, 2] <= 0.0)
    assert np.all(f[outside] == 0.0)
    assert np.all(pdf[outside] == 0.0)


@FAST
@given(material=reciprocal_materials(), pair=direction_pairs())
def test_reciprocal_models_are_reciprocal(
    material: Material, pair: tuple[np.ndarray, np.ndarray]
) -> None:
    wi, wo = pair
    np.testing.assert_allclose(
        material.eval_local(wi, wo), material.eval_local(wo, wi), rtol=1e-9, atol=1e-300
    )


@FAST
@given(
    ks=st.floats(0.1, 1.0),
    m=st.floats(0.05, 1.0),
    n2=st.floats(1.1, 3.0),
    theta_i=st.floats(5.0, 40.0),
    theta_o=st.floats(50.0, 85.0),
)
def test_cook_torrance_with_the_papers_incidence_fresnel_is_not_reciprocal(
    ks: float, m: float, n2: float, theta_i: float, theta_o: float
) -> None:
    mat = CookTorrance(kd=0.0, ks=ks, m=m, n2=n2, fresnel_angle="incidence")
    wi = np.array([_unit(math.cos(math.radians(theta_i)), 0.0)])
    wo = np.array([_unit(math.cos(math.radians(theta_o)), math.pi)])
    forward, backward = mat.eval_local(wi, wo)[0], mat.eval_local(wo, wi)[0]
    assume(forward > 1e-250)  # D underflows far off-specular for small m
    assert not math.isclose(forward, backward, rel_tol=1e-6)


@FAST
@given(
    material=materials(),
    wo=st.lists(directions(below=True), min_size=1, max_size=8),
    seed=st.integers(0, 2**32 - 1),
)
def test_sample_pdf_equals_pdf_local_and_weight_equals_f_cos_over_pdf(
    material: Material, wo: list[tuple[float, float, float]], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    wo_arr = np.array(wo, dtype=float)[rng.integers(0, len(wo), 64)]
    s = material.sample_local(wo_arr, uniforms(rng, 64))
    assert s.wi.shape == (64, 3) and s.pdf.shape == s.weight.shape == (64,)
    assert np.all(np.isfinite(s.wi)) and np.all(np.isfinite(s.pdf))
    assert np.all(np.isfinite(s.weight)) and np.all(s.weight >= 0.0)
    np.testing.assert_array_equal(material.pdf_local(s.wi, wo_arr), s.pdf)
    ok = s.pdf > 0.0
    assert np.all(s.weight[~ok] == 0.0)
    assert np.all(s.wi[ok, 2] > 0.0) and np.all(wo_arr[ok, 2] > 0.0)
    np.testing.assert_allclose(np.linalg.norm(s.wi[ok], axis=1), 1.0, atol=1e-9)
    f = material.eval_local(s.wi[ok], wo_arr[ok])
    np.testing.assert_allclose(s.weight[ok], f * s.wi[ok, 2] / s.pdf[ok], rtol=1e-12)


@FAST
@given(material=materials(), pair=direction_pairs())
def test_pdf_is_positive_wherever_the_brdf_is(
    material: Material, pair: tuple[np.ndarray, np.ndarray]
) -> None:
    # Otherwise the sampling estimator would silently miss energy. Where f cos θi is itself
    # near float64 underflow (cos θi = 5e-324, kd = 1e-300) the density may underflow too;
    # 1e-280 keeps the check far from that and still covers every contribution that matters.
    wi, wo = pair
    f = material.eval_local(wi, wo)
    pdf = material.pdf_local(wi, wo)
    assert np.all(pdf[f * wi[:, 2] > 1e-280] > 0.0)


@SLOW
@given(
    material=materials(),
    wo=st.lists(directions(), min_size=1, max_size=3),
    seed=st.integers(0, 2**32 - 1),
)
def test_albedo_never_exceeds_one(
    material: Material, wo: list[tuple[float, float, float]], seed: int
) -> None:
    wos = np.array([w for w in wo if w[2] > 0.0])
    assume(len(wos) > 0)
    smooth = isinstance(material, (Lambertian, Hapke))  # quadrature resolves these
    check_albedo_at_most_one(
        material, wos, n_samples=20_000, seed=seed % 2**31, use_quadrature=smooth
    )


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


@FAST
@given(material=materials(), seed=st.integers(0, 2**32 - 1))
def test_world_frame_wrappers_agree_with_the_local_frame_for_any_normal(
    material: Material, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    n = 32
    z = rng.uniform(0.05, 1.0, (2, n))  # away from the horizon: rotations round by ~1e-16
    phi = rng.uniform(0.0, 2 * np.pi, (2, n))
    wi = np.array([_unit(a, b) for a, b in zip(z[0], phi[0], strict=True)])
    wo = np.array([_unit(a, b) for a, b in zip(z[1], phi[1], strict=True)])
    rot = _random_rotation(rng)
    normals = np.tile(rot[:, 2], (n, 1))
    normals[0] = (0.0, 0.0, -1.0)  # the branch of the frame construction at z = -1
    flip = np.eye(3) * np.array([1.0, 1.0, -1.0])  # maps (0, 0, 1) to (0, 0, -1)
    wi_w, wo_w = wi @ rot.T, wo @ rot.T
    wi_w[0], wo_w[0] = flip @ wi[0], flip @ wo[0]
    np.testing.assert_allclose(
        material.evaluate(wi_w, wo_w, normals), material.eval_local(wi, wo), rtol=1e-6
    )
    np.testing.assert_allclose(
        material.pdf(wi_w, wo_w, normals), material.pdf_local(wi, wo), rtol=1e-6
    )
    s = material.sample(wo_w, normals, uniforms(rng, n))
    ok = s.pdf > 0.0
    assert np.all(np.einsum("ij,ij->i", s.wi[ok], normals[ok]) > 0.0)
    assert np.all(np.isfinite(s.weight)) and np.all(s.weight >= 0.0)


@FAST
@given(material=materials(), wo=directions(), seed=st.integers(0, 2**32 - 1))
def test_normals_at_the_horizon_give_finite_nonnegative_results(
    material: Material, wo: tuple[float, float, float], seed: int
) -> None:
    # Normals perpendicular to wo (the view grazes the surface exactly), plus wi == wo.
    rng = np.random.default_rng(seed)
    n = 16
    wo_arr = np.tile(np.array(wo), (n, 1))
    t = rng.normal(size=(n, 3))
    normals = np.cross(wo_arr, t)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi[0] = wo
    for values in (
        material.evaluate(wi, wo_arr, normals),
        material.pdf(wi, wo_arr, normals),
        material.sample(wo_arr, normals, uniforms(rng, n)).weight,
    ):
        assert np.all(np.isfinite(values)) and np.all(values >= 0.0)


# -------------------------------------------------------------------------------------------
# Lobe choice of the microfacet models (issue 16)
# -------------------------------------------------------------------------------------------
def microfacets() -> st.SearchStrategy[SeedMicrofacet | CookTorrance]:
    return st.one_of(seed_microfacets(), cook_torrances())


#: view cosines at the edges: the SPECIAL_Z, below the horizon, and rounding just past +-1
EDGE_WOZ = [*SPECIAL_Z, -1e-300, -0.5, -1.0, 1.0 + 2e-16, -1.0 - 2e-16]


@FAST
@given(material=microfacets(), woz=st.one_of(st.sampled_from(EDGE_WOZ), st.floats(-1.0, 1.0)))
def test_lobe_probabilities_are_a_distribution_over_the_lobes_present(
    material: SeedMicrofacet | CookTorrance, woz: float
) -> None:
    p_spec, p_diff = kn.lobe_probabilities(material.kernel_kind, material.kernel_params(), woz)
    assert math.isfinite(p_spec) and math.isfinite(p_diff)
    assert 0.0 <= p_spec <= 1.0 and 0.0 <= p_diff <= 1.0
    # a lobe is sampled exactly when it is present (ks = 0 or kd = 0: never; black: neither)
    assert (p_spec > 0.0) == (material.ks > 0.0)
    assert (p_diff > 0.0) == (material.kd > 0.0)
    if material.ks > 0.0 or material.kd > 0.0:
        assert p_spec + p_diff == pytest.approx(1.0, abs=1e-15)
    if material.ks > 0.0 and material.kd > 0.0:
        # never starved: a specular albedo estimate of 0 (F0 = 0 at normal view, n2 = 1) must
        # not leave a lobe with positive values unsampled
        assert p_spec >= kn.P_SPEC_MIN


@FAST
@given(material=microfacets(), woz=st.one_of(st.sampled_from(SPECIAL_Z), st.floats(0.0, 1.0)))
def test_the_mirror_fresnel_is_a_fraction(
    material: SeedMicrofacet | CookTorrance, woz: float
) -> None:
    fresnel = kn.mirror_fresnel(material.kernel_kind, material.kernel_params(), woz)
    assert 0.0 <= fresnel <= 1.0


@FAST
@given(material=st.one_of(seed_microfacets(both_lobes=True), cook_torrances(both_lobes=True)),
       woz=st.one_of(st.sampled_from(SPECIAL_Z), st.floats(0.0, 1.0)))
def test_lobes_are_chosen_in_proportion_to_their_albedo_at_wo(
    material: SeedMicrofacet | CookTorrance, woz: float
) -> None:
    kind, p = material.kernel_kind, material.kernel_params()
    fresnel = kn.mirror_fresnel(kind, p, woz)
    assert material.ks > 0.0 and material.kd > 0.0
    p_spec, p_diff = kn.lobe_probabilities(kind, p, woz)
    a_spec, a_diff = material.ks * fresnel, material.kd
    if a_spec >= kn.P_SPEC_MIN / (1.0 - kn.P_SPEC_MIN) * a_diff * (1.0 + 1e-9):
        assert p_spec * a_diff == pytest.approx(p_diff * a_spec, rel=1e-12)
    else:
        assert (p_spec, p_diff) == (kn.P_SPEC_MIN, 1.0 - kn.P_SPEC_MIN)


@FAST
@given(material=microfacets(), p_fixed=bounded(kn.P_SPEC_MIN, kn.U_MAX, 0.5),
       woz=st.one_of(st.sampled_from(SPECIAL_Z), st.floats(0.0, 1.0)))
def test_fixed_lobes_keep_their_probabilities_and_the_brdf(
    material: SeedMicrofacet | CookTorrance, p_fixed: float, woz: float
) -> None:
    kind, p = material.kernel_kind, material.kernel_params()
    q = kn.fixed_lobes(p, p_fixed)
    p_spec, p_diff = kn.lobe_probabilities(kind, q, woz)
    assert p_spec == p_fixed
    assert p_diff == pytest.approx(1.0 - p_fixed, rel=1e-12, abs=1e-16)
    wi = np.array([[0.3, 0.1, math.sqrt(0.9)], [0.0, 0.0, 1.0]])
    wo = np.array([_unit(woz, 2.0)] * 2)
    np.testing.assert_array_equal(kn.eval_batch(kind, q, wi, wo), material.eval_local(wi, wo))
