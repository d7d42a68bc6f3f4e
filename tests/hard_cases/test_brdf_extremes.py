"""BRDFs at the bounds of their parameters, built through ``make_material`` and evaluated through
the compiled kernels the renderer calls.

What tests/sim_core/materials already covers is not repeated (finiteness over random
parameters and directions, the most reflective parameters' albedo, rejection far outside the
ranges). Added here: the exact bounds through the factory, black surfaces at grazing angles,
normals facing away, the albedo of full-strength mixtures (kd + ks = 1) at 89.99 degrees and
beyond, continuity of the Fresnel terms at their bounds, and stability: a parameter moved by
1e-9 relative moves the BRDF by at most a stated Lipschitz bound.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError
from sim_core.materials import (
    CookTorrance,
    Hapke,
    Lambertian,
    Material,
    SeedMicrofacet,
    make_material,
)
from sim_core.materials import kernels as kn
from sim_core.materials.hapke import hapke_max_w
from tests.sim_core.materials.harness import check_albedo_at_most_one, direction_deg, repeat

GRAZING = [89.99, 89.9999, 90.0 - 1e-9]


def unit(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    return direction_deg(theta_deg, phi_deg)


# -------------------------------------------------------------------------------------------
# The bounds through the factory
# -------------------------------------------------------------------------------------------
BOUNDS = {
    "seed-microfacet": {"sigma": (1e-6, 1.0), "f0": (0.0, 1.0), "fresnel_exponent": (0.0, 100.0),
                        "ks": (0.0, 1.0), "kd": (0.0, 1.0)},
    "cook-torrance": {"m": (1e-6, 1.0), "n2": (1.0, 3.0), "ks": (0.0, 1.0), "kd": (0.0, 1.0)},
    "lambertian": {"albedo": (0.0, 1.0)},
    "hapke": {"b0": (0.0, 2.0), "h": (0.0, 1.0), "phase_b": (-1.0, 1.0)},
}
BOUND_CASES = [(kind, field, lo, hi) for kind, fields in BOUNDS.items()
               for field, (lo, hi) in fields.items()]


def _base(kind: str, field: str) -> dict:
    # the other lobe off, so that ks or kd alone may reach 1
    if kind in ("seed-microfacet", "cook-torrance"):
        return {"ks": 0.0, "kd": 0.0}
    return {"w": 0.3} if kind == "hapke" else {}


@pytest.mark.parametrize(("kind", "field", "lo", "hi"), BOUND_CASES,
                         ids=[f"{k}-{f}" for k, f, _, _ in BOUND_CASES])
def test_factory_accepts_each_bound_exactly_and_rejects_the_next_float_outside(
    kind, field, lo, hi
):
    base = _base(kind, field)
    for value in (lo, hi, int(lo) if float(lo).is_integer() else lo):
        m = make_material(kind, **{**base, field: value})
        assert getattr(m, field) == value and isinstance(getattr(m, field), float)
        assert m.kernel_params().shape == (kn.N_PARAMS,)
        assert np.all(np.isfinite(m.kernel_params()))
    for value in (np.nextafter(lo, -np.inf), np.nextafter(hi, np.inf)):
        with pytest.raises(InvalidInputError) as err:
            make_material(kind, **{**base, field: float(value)})
        assert err.value.field == field


def test_hapke_single_scattering_albedo_is_accepted_up_to_its_energy_limit():
    w_max = hapke_max_w(2.0, 1.0, 1.0)
    Hapke(w=w_max, b0=2.0, h=1.0, phase_b=1.0)
    with pytest.raises(InvalidInputError):
        Hapke(w=min(1.0, w_max * (1.0 + 1e-6)), b0=2.0, h=1.0, phase_b=1.0)


# -------------------------------------------------------------------------------------------
# Black surfaces and normals facing away
# -------------------------------------------------------------------------------------------
BLACK = [
    make_material("seed-microfacet", ks=0.0, kd=0.0, sigma=1e-6, f0=1.0, fresnel_exponent=0.0),
    make_material("seed-microfacet", ks=0.0, kd=0.0, sigma=1.0),
    make_material("cook-torrance", ks=0.0, kd=0.0, m=1e-6, n2=3.0),
    make_material("cook-torrance", ks=0.0, kd=0.0, m=1.0, n2=1.0, fresnel_angle="half"),
    make_material("cook-torrance", ks=1.0, kd=0.0, m=0.3, n2=1.0),  # index-matched: F = 0
    make_material("lambertian", albedo=0.0),
    make_material("hapke", w=0.0, b0=2.0, h=1.0, phase_b=1.0),
]


@pytest.mark.parametrize("material", BLACK, ids=repr)
@pytest.mark.parametrize("theta_o", [0.0, 60.0, *GRAZING])
def test_black_surfaces_reflect_nothing_even_at_grazing_angles(material, theta_o):
    n = 2000
    rng = np.random.default_rng(0)
    wo = repeat(unit(theta_o, 17.0), n)
    s = material.sample_local(wo, rng.random((n, 3)))
    assert np.all(s.weight == 0.0)
    wi = np.concatenate([s.wi[s.pdf > 0], repeat(unit(theta_o, 197.0), 1), wo[:1]])
    assert np.all(material.eval_local(wi, repeat(wo[0], len(wi))) == 0.0)
    assert material.albedo_bound == 0.0 or isinstance(material, CookTorrance)


EXTREME = [
    make_material("seed-microfacet", ks=1.0, kd=0.0, sigma=1e-6, f0=1.0, fresnel_exponent=0.0),
    make_material("seed-microfacet", ks=0.5, kd=0.5, sigma=1.0, f0=0.0, fresnel_exponent=100.0),
    make_material("cook-torrance", ks=1.0, kd=0.0, m=1e-6, n2=3.0, fresnel_angle="half"),
    make_material("cook-torrance", ks=0.5, kd=0.5, m=1.0, n2=3.0),
    make_material("lambertian", albedo=1.0),
    Hapke(w=hapke_max_w(2.0, 1.0, 1.0), b0=2.0, h=1.0, phase_b=1.0),
]


@pytest.mark.parametrize("material", EXTREME, ids=repr)
def test_normal_facing_away_from_both_directions_reflects_nothing(material):
    # World frame: wi and wo above the true surface, the normal given reversed. The contract
    # makes both directions "below the horizon": value, density and samples all vanish (the
    # renderer turns normals towards the ray before it calls the BRDF: two-sided shading).
    rng = np.random.default_rng(1)
    k = 64
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    wo = repeat(unit(89.99, 10.0), k)
    wo[: k // 2] = repeat(unit(30.0, 10.0), k // 2)
    wi = repeat(unit(89.99, 190.0), k)
    assert np.all(material.evaluate(wi, wo, n) >= 0.0)
    assert np.all(material.evaluate(wi, wo, -n) == 0.0)
    assert np.all(material.pdf(wi, wo, -n) == 0.0)
    s = material.sample(wo, -n, rng.random((k, 3)))
    assert np.all(s.weight == 0.0) and np.all(s.pdf == 0.0)
    # Flipping every vector together with the normal changes nothing.
    np.testing.assert_allclose(material.evaluate(-wi, -wo, -n), material.evaluate(wi, wo, n),
                               rtol=1e-9)


# -------------------------------------------------------------------------------------------
# Albedo at grazing view with both lobes at full strength
# -------------------------------------------------------------------------------------------
FULL_MIXTURES = [
    SeedMicrofacet(ks=0.5, kd=0.5, sigma=1e-6, f0=1.0, fresnel_exponent=0.0),
    SeedMicrofacet(ks=0.5, kd=0.5, sigma=1.0, f0=1.0, fresnel_exponent=0.0),
    SeedMicrofacet(ks=0.9, kd=0.1, sigma=1e-6, f0=0.0, fresnel_exponent=100.0),
    CookTorrance(kd=0.5, ks=0.5, m=1e-6, n2=3.0, fresnel_angle="half"),
    CookTorrance(kd=0.5, ks=0.5, m=1.0, n2=3.0),
    CookTorrance(kd=0.1, ks=0.9, m=1e-6, n2=3.0),
    Hapke(w=hapke_max_w(2.0, 0.01, 1.0), b0=2.0, h=0.01, phase_b=1.0),
]


@pytest.mark.parametrize("material", FULL_MIXTURES, ids=repr)
def test_albedo_of_full_strength_mixtures_stays_below_one_at_grazing_view(material):
    # Near grazing the specular lobe of n2 = 3 (or F0 = 1) reflects almost everything and the
    # diffuse lobe adds its kd: the sum must still stay <= 1.
    wos = np.stack([unit(t, 40.0) for t in (0.0, 60.0, 89.0, *GRAZING[:2])])
    check_albedo_at_most_one(material, wos, n_samples=20_000, seed=3)


@pytest.mark.parametrize("material", EXTREME + FULL_MIXTURES, ids=repr)
@pytest.mark.parametrize("theta_o", GRAZING)
def test_samples_at_grazing_view_are_finite_and_consistent(material, theta_o):
    n = 4000
    wo = repeat(unit(theta_o, 5.0), n)
    s = material.sample_local(wo, np.random.default_rng(2).random((n, 3)))
    assert np.all(np.isfinite(s.wi)) and np.all(np.isfinite(s.pdf))
    assert np.all(np.isfinite(s.weight)) and np.all(s.weight >= 0.0)
    ok = s.pdf > 0.0
    f = material.eval_local(s.wi[ok], wo[ok])
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    np.testing.assert_allclose(s.weight[ok], f * s.wi[ok, 2] / s.pdf[ok], rtol=1e-12)


# -------------------------------------------------------------------------------------------
# The Fresnel terms at their bounds
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta_deg", [0.0, 60.0, 89.0, 89.99])
def test_dielectric_fresnel_vanishes_continuously_as_n2_approaches_one(theta_deg):
    # F(n2 = 1) = 0 exactly. Just above, F is not Lipschitz in n2 at grazing incidence (the
    # Fresnel equations go like ((n2 - 1) / (2 cos^2))^2 / 4 for n2 - 1 << cos^2), but it is
    # continuous: the bound below shrinks to 0 with n2 - 1.
    c = math.cos(math.radians(theta_deg))
    assert kn.fresnel_dielectric(c, 1.0) == 0.0
    for delta in (1e-12, 1e-9, 1e-6):
        f = kn.fresnel_dielectric(c, 1.0 + delta)
        assert 0.0 <= f <= 2.0 * (delta / (2.0 * c * c)) ** 2 + delta
    # and it tends to 1 at exact grazing incidence for any index mismatch
    assert kn.fresnel_dielectric(0.0, 1.0 + 1e-9) == pytest.approx(1.0)


def test_lower_bounds_that_jump_at_retro_reflection_which_the_co_located_source_sees():
    # With the source at the camera, wi == wo for all direct light (retro-reflection):
    # - Schlick: cos(gamma) = 1, so F = F0 + (1 - F0) 0^n is 1 for n = 0 (0^0 = 1, as
    #   documented) but F0 for every n > 0;
    # - Hapke: g = 0, so B = B0 h / (h + tan(g/2)) is B0 for every h > 0 but 0 for h = 0
    #   ("no surge", as documented).
    # These lower bounds are discontinuities of the models themselves (not of their code),
    # and the ToF geometry sits on them at every pixel: stated here so that they stay known.
    assert kn.fresnel_schlick_power(1.0, 0.25, 0.0) == 1.0
    for n in (1e-300, 1e-9, 1.0, 100.0):
        assert kn.fresnel_schlick_power(1.0, 0.25, n) == 0.25
    retro = repeat(unit(30.0), 1)
    no_surge = Hapke(w=0.5, b0=2.0, h=0.0, phase_b=0.0).eval_local(retro, retro)[0]
    narrow = Hapke(w=0.5, b0=2.0, h=1e-9, phase_b=0.0).eval_local(retro, retro)[0]
    assert narrow > 1.5 * no_surge
    # Off the exact retro-reflection both are continuous at the bound.
    for cos_gamma in (0.0, 0.5, 1.0 - 1e-12):
        f0 = kn.fresnel_schlick_power(cos_gamma, 0.25, 0.0)
        assert kn.fresnel_schlick_power(cos_gamma, 0.25, 1e-9) == pytest.approx(f0, abs=1e-7)
    off = repeat(unit(30.0, 1.0), 1)
    a = Hapke(w=0.5, b0=2.0, h=0.0, phase_b=0.0).eval_local(off, retro)[0]
    b = Hapke(w=0.5, b0=2.0, h=1e-9, phase_b=0.0).eval_local(off, retro)[0]
    assert b == pytest.approx(a, rel=1e-6)


# -------------------------------------------------------------------------------------------
# Stability: a parameter moved by 1e-9 relative
# -------------------------------------------------------------------------------------------
EPS = 1e-9
#: Lipschitz constant of ln f in the log of each parameter, over values that do not underflow:
#: the Beckmann exponent tan^2 / alpha^2 <= 745 (beyond, exp() underflows) gives
#: |d ln D / d ln alpha| <= 2 + 2 * 745; every other parameter enters linearly, through
#: x^n e^{...} (|n ln x| x^n <= 1/e) or smoothly (Hapke's w <= 0.78, h, b0, b).
LIPSCHITZ = 2000.0


def magnitude(material: Material, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The size of the BRDF's terms per unit of their coefficients at each pair (kd, ks, F0,
    albedo, w <= 1 and the Fresnel factor <= 1 taken as 1): the scale against which a change
    is measured. It bounds the change of a coefficient moved from 0 to 1e-9 as well as the
    relative moves, and it does not vanish where the terms cancel (Hapke's bracket)."""
    if isinstance(material, Lambertian):
        return np.full(len(wi), 1.0 / math.pi)
    if isinstance(material, Hapke):
        p = material.kernel_params()
        mu_i, mu_o = np.clip(wi[:, 2], 0.0, 1.0), np.clip(wo[:, 2], 0.0, 1.0)
        h = np.array([kn.chandrasekhar_h(a, p[4]) * kn.chandrasekhar_h(b, p[4])
                      for a, b in zip(mu_i, mu_o, strict=True)])
        bracket = 2.0 * (1.0 + p[1]) + h + 1.0
        return bracket / (4.0 * math.pi) / np.maximum(mu_i + mu_o, kn.COS_EPS)
    dg = np.array([kn.torrance_sparrow_dg(*a, *b, material.alpha)[0]
                   for a, b in zip(wi, wo, strict=True)])
    return 1.0 / math.pi + dg


def _near(lo: float, hi: float, *specials: float):
    return st.one_of(st.sampled_from([lo, hi, *specials]), st.floats(lo, hi))


@st.composite
def stable_materials(draw):
    kind = draw(st.sampled_from(["seed", "ct", "lambert", "hapke"]))
    if kind in ("seed", "ct"):
        ks = draw(_near(0.0, 1.0))
        kd = draw(st.one_of(st.just(1.0 - ks), st.just(0.0), st.floats(0.0, 1.0 - ks)))
        if kind == "seed":
            return SeedMicrofacet(ks=ks, kd=kd, sigma=draw(_near(1e-6, 1.0, 0.014)),
                                  f0=draw(_near(0.0, 1.0)),
                                  fresnel_exponent=draw(_near(0.0, 100.0, 5.0)))
        # n2 -> 1 is not Lipschitz at grazing incidence (see the test above): kept >= 1.01
        return CookTorrance(kd=kd, ks=ks, m=draw(_near(1e-6, 1.0)), n2=draw(_near(1.01, 3.0)),
                            fresnel_angle=draw(st.sampled_from(["incidence", "half"])))
    if kind == "lambert":
        return Lambertian(albedo=draw(_near(0.0, 1.0)))
    return Hapke(w=draw(_near(0.0, 0.78)), b0=draw(_near(0.0, 2.0)), h=draw(_near(0.0, 1.0)),
                 phase_b=draw(_near(-1.0, 1.0)))


GRAZING_Z = [math.cos(math.radians(t)) for t in GRAZING] + [1e-12, 1.0, math.sqrt(0.5)]


@st.composite
def direction_pairs(draw):
    n = draw(st.integers(1, 8))
    wi, wo = [], []
    for _ in range(n):
        z = draw(st.one_of(st.sampled_from(GRAZING_Z), st.floats(1e-12, 1.0)))
        phi = draw(st.floats(0.0, 2.0 * math.pi))
        s = math.sqrt(1.0 - z * z)
        a = (s * math.cos(phi), s * math.sin(phi), z)
        relation = draw(st.sampled_from(["free", "same", "mirror", "near-mirror"]))
        if relation == "free":
            z2 = draw(st.one_of(st.sampled_from(GRAZING_Z), st.floats(1e-12, 1.0)))
            phi2 = draw(st.floats(0.0, 2.0 * math.pi))
            s2 = math.sqrt(1.0 - z2 * z2)
            b = (s2 * math.cos(phi2), s2 * math.sin(phi2), z2)
        elif relation == "same":
            b = a
        else:
            tilt = 0.0 if relation == "mirror" else draw(st.floats(-1e-3, 1e-3))
            b = (-a[0] + tilt, -a[1], a[2])
            b = tuple(np.array(b) / np.linalg.norm(b))
        wi.append(a)
        wo.append(b)
    return np.array(wi), np.array(wo)


#: (model, parameter) pairs whose lower bound 0 is a jump of the model at the retro-reflection
#: wi == wo (see the test above); everywhere else a move from 0 to 1e-9 is a small change
JUMPS_AT_ZERO = {(SeedMicrofacet, "fresnel_exponent"), (Hapke, "h")}


def _moved(material: Material, field: str, sign: float) -> Material | None:
    value = getattr(material, field)
    if value == 0.0 and (type(material), field) in JUMPS_AT_ZERO:
        return None
    new = value * (1.0 + sign * EPS) if value != 0.0 else max(sign, 0.0) * EPS
    try:
        return dataclasses.replace(material, **{field: new})
    except InvalidInputError:  # past a bound (or ks + kd > 1): not a valid perturbation
        return None


NUMERIC_FIELDS = {
    SeedMicrofacet: ("ks", "kd", "sigma", "f0", "fresnel_exponent"),
    CookTorrance: ("kd", "ks", "m", "n2"),
    Lambertian: ("albedo",),
    Hapke: ("w", "b0", "h", "phase_b"),
}


@settings(max_examples=150, deadline=None)
@given(material=stable_materials(), pair=direction_pairs(), sign=st.sampled_from([-1.0, 1.0]))
def test_a_parameter_moved_by_1e_9_relative_moves_the_brdf_by_a_bounded_amount(
    material, pair, sign
):
    wi, wo = pair
    f = material.eval_local(wi, wo)
    for field in NUMERIC_FIELDS[type(material)]:
        moved = _moved(material, field, sign)
        if moved is None:
            continue
        g = moved.eval_local(wi, wo)
        scale = np.maximum(magnitude(material, wi, wo), magnitude(moved, wi, wo))
        # 1e-280: below it the Beckmann term is subnormal and has no relative precision left
        bound = LIPSCHITZ * EPS * scale + 1e-280
        assert np.all(np.abs(g - f) <= bound), (field, np.abs(g - f) / np.maximum(scale, 1e-300))
