"""Tests of the compiled material kernels (``sim_core.materials.kernels``) as the integrator
sees them: the scalar kernels agree with the batch API the numpy methods use, ``sample_brdf``
reports ``pdf_brdf`` at the direction it samples, and the signatures work from other
``@njit`` functions, serial and parallel, with a material table like the renderer's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit, prange

from sim_core.materials import (
    PRESETS,
    CookTorrance,
    Hapke,
    Lambertian,
    Material,
    SeedMicrofacet,
    material_preset,
)
from sim_core.materials import kernels as kn
from sim_core.materials.base import finish_sample

MATERIALS: list[Material] = [
    *(material_preset(name) for name in PRESETS),
    SeedMicrofacet(ks=1.0, kd=0.0, fresnel_exponent=0.0, sigma=1e-6, f0=1.0),
    SeedMicrofacet(ks=0.0, kd=0.0),
    SeedMicrofacet(ks=1.0 - 1e-250, kd=1e-250, sigma=1e-6),
    CookTorrance(kd=0.2, ks=0.8, m=0.6, n2=3.0, fresnel_angle="half"),
    CookTorrance(kd=0.0, ks=1.0, m=1e-6, n2=1.0, fresnel_angle="incidence"),
    Lambertian(albedo=0.0),
    Lambertian(albedo=1.0),
    Hapke(w=0.5, b0=2.0, h=0.0, phase_b=1.0),
    Hapke(w=0.0, b0=0.0, h=0.0, phase_b=-1.0),
]
IDS = [repr(m) for m in MATERIALS]

#: cosines of special polar angles, including tangent and below the horizon
SPECIAL_Z = [1.0, math.sqrt(0.5), math.cos(math.radians(89.99)), 1e-12, 1e-300, 0.0, -1e-300, -0.5]


def directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Unit vectors (n, 3) over the whole sphere, special polar angles drawn often."""
    z = np.where(rng.random(n) < 0.3, rng.choice(SPECIAL_Z, n), rng.uniform(-1.0, 1.0, n))
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def pairs(seed: int, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """``wi``, ``wo`` with coincident, mirror and opposite pairs mixed in."""
    rng = np.random.default_rng(seed)
    wi, wo = directions(rng, n), directions(rng, n)
    k = n // 8
    wi[:k] = wo[:k]
    wi[k : 2 * k] = wo[k : 2 * k] * np.array([-1.0, -1.0, 1.0])
    wi[2 * k : 3 * k] = -wo[2 * k : 3 * k]
    return wi, wo


def uniforms(seed: int, n: int) -> np.ndarray:
    u = np.random.default_rng(seed).random((n, 3))
    u[:4] = [[0.0, 0.0, 0.0], [kn.U_MAX] * 3, [0.0, kn.U_MAX, 0.5], [1.0, 1.0, 1.0]]
    return u


# -------------------------------------------------------------------------------------------
# Parameter vectors
# -------------------------------------------------------------------------------------------
def test_every_model_has_its_own_kind_and_a_full_float64_parameter_vector() -> None:
    kinds = {
        Lambertian: kn.KIND_LAMBERTIAN,
        SeedMicrofacet: kn.KIND_SEED_MICROFACET,
        CookTorrance: kn.KIND_COOK_TORRANCE,
        Hapke: kn.KIND_HAPKE,
    }
    assert len(set(kinds.values())) == 4
    for cls, kind in kinds.items():
        assert cls.kernel_kind == kind
    for m in MATERIALS:
        p = m.kernel_params()
        assert isinstance(m.kernel_kind, int)
        assert p.shape == (kn.N_PARAMS,) and p.dtype == np.float64
        assert np.all(np.isfinite(p))


def test_parameter_vectors_carry_the_documented_values() -> None:
    np.testing.assert_array_equal(
        Lambertian(albedo=0.3).kernel_params(), [0.3, 0.3 / math.pi, 0, 0, 0, 0, 0, 0]
    )
    s = SeedMicrofacet(ks=0.6, kd=0.2, fresnel_exponent=5.0, sigma=0.02, f0=0.1)
    np.testing.assert_array_equal(
        s.kernel_params(), [s.alpha, 0.6, 0.2, 0.2 / math.pi, 0.6, 0.1, 5.0, 1.0]
    )
    for angle, flag in (("incidence", 0.0), ("half", 1.0)):
        c = CookTorrance(kd=0.3, ks=0.5, m=0.2, n2=1.5, fresnel_angle=angle)
        np.testing.assert_array_equal(
            c.kernel_params(), [0.2, 0.5, 0.3, 0.3 / math.pi, 0.5, 1.5, flag, 1.0]
        )
    h = Hapke(w=0.36, b0=1.5, h=0.2, phase_b=-0.4)
    np.testing.assert_array_equal(
        h.kernel_params(), [0.36, 1.5, 0.2, -0.4, 0.8, 0.36 / (4 * math.pi), 1.5 * 0.2, 0.0]
    )
    # A black microfacet surface has no lobe to pick: both weights 0.
    assert SeedMicrofacet(ks=0.0, kd=0.0).kernel_params()[1:3].tolist() == [0.0, 0.0]
    # The naive mixture of issue 16: fixed probabilities, no Fresnel factor, same BRDF.
    q = kn.fixed_lobes(c.kernel_params(), 0.5)
    np.testing.assert_array_equal(q[[1, 2, 7]], [0.5, 0.5, 0.0])
    np.testing.assert_array_equal(np.delete(q, [1, 2, 7]), np.delete(c.kernel_params(), [1, 2, 7]))
    for bad in (0.0, 0.04, 1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="outside"):
            kn.fixed_lobes(c.kernel_params(), bad)


def test_parameter_vector_of_a_wrong_shape_is_rejected() -> None:
    class Broken(Lambertian):
        def kernel_params(self) -> np.ndarray:
            return np.zeros(3)

    with pytest.raises(ValueError, match="kernel_params"):
        Broken().eval_local(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))


def test_direction_arrays_of_a_wrong_shape_are_rejected() -> None:
    m = Lambertian()
    z = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="wi must have shape"):
        m.eval_local(np.array([0.0, 0.0, 1.0]), z)
    with pytest.raises(ValueError, match="same shape"):
        m.pdf_local(np.repeat(z, 2, 0), z)
    with pytest.raises(ValueError, match="u must have the shape"):
        m.sample_local(z, np.zeros((2, 3)))


# -------------------------------------------------------------------------------------------
# Scalar kernels vs the batch API
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("material", MATERIALS, ids=IDS)
def test_scalar_kernels_agree_bit_for_bit_with_the_batch_api(material: Material) -> None:
    kind, p = material.kernel_kind, material.kernel_params()
    wi, wo = pairs(1)
    f = np.array([kn.eval_brdf(kind, p, *a, *b) for a, b in zip(wi, wo, strict=True)])
    pdf = np.array([kn.pdf_brdf(kind, p, *a, *b) for a, b in zip(wi, wo, strict=True)])
    np.testing.assert_array_equal(f, material.eval_local(wi, wo))
    np.testing.assert_array_equal(f, kn.eval_batch(kind, p, wi, wo))
    np.testing.assert_array_equal(pdf, material.pdf_local(wi, wo))
    np.testing.assert_array_equal(pdf, kn.pdf_batch(kind, p, wi, wo))

    u = uniforms(2, len(wo))
    scalar = np.array([kn.sample_brdf(kind, p, *w, *v) for w, v in zip(wo, u, strict=True)])
    s = material.sample_local(wo, u)
    np.testing.assert_array_equal(scalar[:, :3], s.wi)
    np.testing.assert_array_equal(scalar[:, 3], s.pdf)
    np.testing.assert_array_equal(scalar[:, 4], s.weight)


@pytest.mark.parametrize("material", MATERIALS, ids=IDS)
def test_sample_pdf_is_pdf_brdf_at_the_sampled_direction(material: Material) -> None:
    kind, p = material.kernel_kind, material.kernel_params()
    rng = np.random.default_rng(3)
    wo = directions(rng, 2000)
    u = uniforms(4, len(wo))
    for w, v in zip(wo, u, strict=True):
        x, y, z, pdf, weight = kn.sample_brdf(kind, p, *w, *v)
        assert pdf == kn.pdf_brdf(kind, p, x, y, z, *w)
        assert math.isfinite(weight) and weight >= 0.0
        if pdf > 0.0:
            assert z > 0.0 and w[2] > 0.0
            assert abs(math.hypot(x, y, z) - 1.0) < 1e-9
            f = kn.eval_brdf(kind, p, x, y, z, *w)
            assert weight == pytest.approx(f * z / pdf, rel=1e-12)
            # exactly the weight the numpy glue computes from eval and pdf
            assert weight == kn.sample_weight(f, z, pdf)
        else:
            assert weight == 0.0


@pytest.mark.parametrize("material", MATERIALS, ids=IDS)
def test_finish_sample_reproduces_the_kernel_sampler(material: Material) -> None:
    # The numpy glue (used for subclasses that override eval_local/pdf_local) and the compiled
    # sampler agree exactly, so both paths honour the same contract.
    wo = directions(np.random.default_rng(5), 500)
    s = material.sample_local(wo, uniforms(6, len(wo)))
    g = finish_sample(material, s.wi, wo)
    np.testing.assert_array_equal(g.pdf, s.pdf)
    np.testing.assert_array_equal(g.weight, s.weight)


def test_unknown_kind_reflects_nothing_and_gives_invalid_samples() -> None:
    p = np.full(kn.N_PARAMS, 0.5)
    z = (0.0, 0.0, 1.0)
    for kind in (-1, 4, 99):
        assert kn.eval_brdf(kind, p, *z, *z) == 0.0
        assert kn.pdf_brdf(kind, p, *z, *z) == 0.0
        _, _, _, pdf, weight = kn.sample_brdf(kind, p, *z, 0.3, 0.6, 0.1)
        assert pdf == 0.0 and weight == 0.0


def test_hapke_batch_is_hapke_f_without_horizon_masking() -> None:
    # The albedo quadrature needs the grazing view mu_o = 0, which eval_brdf masks to 0.
    p = Hapke().kernel_params()
    mu_i = np.array([0.5, 1.0, 0.0, 0.2])
    mu_o = np.array([0.0, 0.3, 0.0, 0.9])
    cos_g = np.array([0.1, 0.3, -1.0, 1.0])
    got = kn.hapke_batch(p, mu_i, mu_o, cos_g)
    expected = [kn.hapke_f(p, a, b, c) for a, b, c in zip(mu_i, mu_o, cos_g, strict=True)]
    np.testing.assert_array_equal(got, expected)
    assert got[0] > 0.0 and np.all(np.isfinite(got))
    grazing = (math.sqrt(1 - 0.25), 0.0, 0.5)
    assert kn.eval_brdf(kn.KIND_HAPKE, p, *grazing, 1.0, 0.0, 0.0) == 0.0


# -------------------------------------------------------------------------------------------
# The integrator's view: kernels called from other compiled functions
# -------------------------------------------------------------------------------------------
@njit
def _mean_weight(kind, p, wo, n):
    """Albedo estimate by a stratified loop over sample_brdf, as a serial integrator would."""
    total = 0.0
    m = int(math.sqrt(n))
    for a in range(m):
        for b in range(m):
            u0 = (a + 0.5) / m
            u1 = (b + 0.5) / m
            u2 = ((a * m + b) * 0.6180339887498949) % 1.0
            _, _, _, _, w = kn.sample_brdf(kind, p, wo[0], wo[1], wo[2], u0, u1, u2)
            total += w
    return total / (m * m)


@njit(parallel=True)
def _shade_like(kinds, table, mat, wi, wo, u):
    """A prange loop over rays with a per-ray material from a table, as the renderer reads it
    (``param_row``: a tuple, not an array row)."""
    n = wi.shape[0]
    f = np.empty(n)
    pdf = np.empty(n)
    sampled = np.empty((n, 5))
    for j in prange(n):
        m = mat[j]
        kind = kinds[m]
        par = kn.param_row(table, m)
        f[j] = kn.eval_brdf(kind, par, wi[j, 0], wi[j, 1], wi[j, 2], wo[j, 0], wo[j, 1], wo[j, 2])
        pdf[j] = kn.pdf_brdf(kind, par, wi[j, 0], wi[j, 1], wi[j, 2], wo[j, 0], wo[j, 1], wo[j, 2])
        x, y, z, q, w = kn.sample_brdf(
            kind, par, wo[j, 0], wo[j, 1], wo[j, 2], u[j, 0], u[j, 1], u[j, 2]
        )
        sampled[j, 0], sampled[j, 1], sampled[j, 2], sampled[j, 3], sampled[j, 4] = x, y, z, q, w
    return f, pdf, sampled


def test_kernels_called_from_a_parallel_njit_loop_with_a_material_table() -> None:
    kinds = np.array([m.kernel_kind for m in MATERIALS], dtype=np.int64)
    table = np.zeros((len(MATERIALS), kn.N_PARAMS))
    for i, m in enumerate(MATERIALS):
        table[i] = m.kernel_params()
    wi, wo = pairs(7, 2000)
    u = uniforms(8, len(wo))
    mat = np.random.default_rng(9).integers(0, len(MATERIALS), len(wo))
    f, pdf, sampled = _shade_like(kinds, table, mat, wi, wo, u)
    for i, m in enumerate(MATERIALS):
        sel = mat == i
        np.testing.assert_array_equal(f[sel], m.eval_local(wi[sel], wo[sel]))
        np.testing.assert_array_equal(pdf[sel], m.pdf_local(wi[sel], wo[sel]))
        s = m.sample_local(wo[sel], u[sel])
        np.testing.assert_array_equal(sampled[sel, :3], s.wi)
        np.testing.assert_array_equal(sampled[sel, 3], s.pdf)
        np.testing.assert_array_equal(sampled[sel, 4], s.weight)


@pytest.mark.parametrize(
    ("material", "albedo"),
    [
        (Lambertian(albedo=0.37), 0.37),
        (Hapke(w=1e-6, b0=0.0, h=0.5), None),
        (material_preset("white-matte-tile"), None),
    ],
    ids=repr,
)
def test_albedo_from_a_serial_njit_caller_matches_the_numpy_api(
    material: Material, albedo: float | None
) -> None:
    wo = np.array([math.sin(0.5), 0.0, math.cos(0.5)])
    got = _mean_weight(material.kernel_kind, material.kernel_params(), wo, 256 * 256)
    rng = np.random.default_rng(10)
    s = material.sample_local(np.tile(wo, (200_000, 1)), rng.random((200_000, 3)))
    assert got == pytest.approx(float(np.mean(s.weight)), rel=2e-2)
    if albedo is not None:
        assert got == pytest.approx(albedo, rel=1e-12)


# -------------------------------------------------------------------------------------------
# Guards at the edges of the parameter ranges
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "material",
    [
        SeedMicrofacet(ks=1.0, kd=0.0, fresnel_exponent=100.0, sigma=1e-6, f0=0.0),
        SeedMicrofacet(ks=0.5, kd=0.5, fresnel_exponent=0.0, sigma=1.0, f0=1.0),
        CookTorrance(kd=0.0, ks=1.0, m=1e-6, n2=3.0, fresnel_angle="half"),
        CookTorrance(kd=0.5, ks=0.5, m=1.0, n2=1.0, fresnel_angle="incidence"),
        Hapke(w=0.78, b0=2.0, h=1.0, phase_b=1.0),
        Hapke(w=0.5, b0=2.0, h=0.0, phase_b=-1.0),
    ],
    ids=repr,
)
def test_no_nan_inf_or_negative_output_at_extreme_parameters(material: Material) -> None:
    kind, p = material.kernel_kind, material.kernel_params()
    wi, wo = pairs(11, 4000)
    # exactly tangent and grazing-by-1e-300 mirror pairs on top of the random ones
    wi[-2:] = [[1.0, 0.0, 0.0], [1.0, 0.0, 1e-300]]
    wo[-2:] = [[-1.0, 0.0, 0.0], [-1.0, 0.0, 1e-300]]
    for values in (kn.eval_batch(kind, p, wi, wo), kn.pdf_batch(kind, p, wi, wo)):
        assert np.all(np.isfinite(values)) and np.all(values >= 0.0)
    s_wi, s_pdf, s_weight = kn.sample_batch(kind, p, wo, uniforms(12, len(wo)))
    assert np.all(np.isfinite(s_wi))
    assert np.all(np.isfinite(s_pdf)) and np.all(s_pdf >= 0.0)
    assert np.all(np.isfinite(s_weight)) and np.all(s_weight >= 0.0)
