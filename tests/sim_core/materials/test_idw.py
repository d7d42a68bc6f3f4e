"""The peer paper's extended inverse distance weighting, eqs. (16)-(17)
(``sim_core.materials.idw``): exact at measured configurations, a convex combination
elsewhere, the weight of eq. (17), isotropy, and its edges."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError
from sim_core.materials import material_preset
from sim_core.materials.goniometer import GoniometerTable
from sim_core.materials.idw import (
    EXACT_DISTANCE_RAD,
    angle_between,
    canonical_pairs,
    configuration_directions,
    idw_interpolate,
)

from .harness import spherical


def sampled_table(name: str = "white-matte-tile", step_deg: float = 10.0) -> GoniometerTable:
    """A goniometer-like table of a preset: zeniths 0-80 deg, azimuths 0-180 deg."""
    z = np.arange(0.0, 80.0 + 1e-9, step_deg)
    ti, tr, ph = np.meshgrid(z, z, np.arange(0.0, 180.0 + 1e-9, 2 * step_deg), indexing="ij")
    wi, wo = configuration_directions(ti, tr, ph)
    f = material_preset(name).eval_local(wi, wo)
    return GoniometerTable(ti.ravel(), tr.ravel(), ph.ravel(), f, source=name)


TABLE = sampled_table()


def rotate_about_normal(w: np.ndarray, angle_rad: float, mirror: bool = False) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    out = np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)
    if mirror:
        out[:, 1] *= -1.0
    return out


def test_measured_configurations_are_reproduced_exactly() -> None:
    """Eq. (16), first case: ρ -> ρ' gives f(ρ'), also for a rotated and mirrored query."""
    wi, wo = TABLE.directions()
    got = idw_interpolate(TABLE, wi, wo)
    oblique = (TABLE.incidence_zenith_deg > 0.0) & (TABLE.reflection_zenith_deg > 0.0)
    np.testing.assert_array_equal(got[oblique], TABLE.brdf_per_sr[oblique])
    # at a zenith direction Δφ is undefined: the rows differing only in Δφ are one
    # configuration (whose values agree to rounding here)
    np.testing.assert_allclose(got[~oblique], TABLE.brdf_per_sr[~oblique], rtol=1e-12)
    for angle, mirror in ((0.7, False), (-2.1, True)):
        got = idw_interpolate(TABLE, rotate_about_normal(wi, angle, mirror),
                              rotate_about_normal(wo, angle, mirror))
        np.testing.assert_allclose(got, TABLE.brdf_per_sr, rtol=1e-12)


def test_two_measurements_are_weighted_by_eq_17() -> None:
    table = GoniometerTable([20.0, 50.0], [30.0, 60.0], [180.0, 90.0], [0.2, 0.8])
    wi = spherical(math.radians(35.0), 0.0)
    wo = spherical(math.radians(40.0), math.radians(150.0))
    l_m, d_m = table.directions()
    dist = [math.acos(float(np.clip(wi[0] @ l_m[k], -1, 1)))
            + math.acos(float(np.clip(wo[0] @ d_m[k], -1, 1))) for k in range(2)]
    w = [d**-5.0 for d in dist]
    expected = (w[0] * 0.2 + w[1] * 0.8) / (w[0] + w[1])
    assert idw_interpolate(table, wi, wo)[0] == pytest.approx(expected, rel=1e-9)
    # u = 1 weighs the far measurement more than u = 5 does
    assert idw_interpolate(table, wi, wo, u=1.0)[0] != pytest.approx(expected, rel=1e-3)


def test_values_lie_between_the_neighbours_extremes() -> None:
    rng = np.random.default_rng(1)
    n = 2000
    wi = spherical(np.arccos(rng.random(n)), rng.uniform(0, 2 * np.pi, n))
    wo = spherical(np.arccos(rng.random(n)), rng.uniform(0, 2 * np.pi, n))
    small = TABLE.subset(np.arange(len(TABLE)) % 7 == 0)
    got = idw_interpolate(small, wi, wo, neighbours=len(small))  # N(ρ): the whole table
    assert np.all(got >= small.brdf_per_sr.min()) and np.all(got <= small.brdf_per_sr.max())
    # with 4 neighbours each value lies between those of its neighbourhood N(ρ): the 4 nearest
    # measurements by the distance of the stacked canonical vectors (l, d)
    got4 = idw_interpolate(TABLE, wi, wo, neighbours=4)
    l_m, d_m = TABLE.directions()
    l_q, d_q = canonical_pairs(wi, wo)
    stacked = np.hstack([l_m, d_m])[None, :, :] - np.hstack([l_q, d_q])[:, None, :]
    near = np.argsort(np.linalg.norm(stacked, axis=2), axis=1)[:, :4]
    f = TABLE.brdf_per_sr[near]
    assert np.all(got4 >= f.min(axis=1) * (1 - 1e-12))
    assert np.all(got4 <= f.max(axis=1) * (1 + 1e-12))


def test_interpolation_is_close_to_the_sampled_model_between_measurements() -> None:
    """Diffuse-dominated material, 10-deg steps: IDW is within 10 % off the specular lobe."""
    rng = np.random.default_rng(2)
    n = 500
    wi = spherical(np.radians(rng.uniform(5, 75, n)), 0.0)
    wo = spherical(np.radians(rng.uniform(5, 75, n)), np.radians(rng.uniform(0, 120, n)))
    truth = material_preset("white-matte-tile").eval_local(wi, wo)
    np.testing.assert_allclose(idw_interpolate(TABLE, wi, wo), truth, rtol=0.1)


def test_angle_between_is_arccos_and_accurate_near_zero() -> None:
    rng = np.random.default_rng(3)
    a = spherical(np.arccos(rng.uniform(-1, 1, 100)), rng.uniform(0, 2 * np.pi, 100))
    b = spherical(np.arccos(rng.uniform(-1, 1, 100)), rng.uniform(0, 2 * np.pi, 100))
    np.testing.assert_allclose(angle_between(a, b), np.arccos(np.sum(a * b, axis=1)), atol=1e-7)
    tiny = spherical(np.array([1e-10]), 0.0)
    assert angle_between(tiny, spherical(0.0))[0] == pytest.approx(1e-10, rel=1e-6)
    assert angle_between(spherical(0.0), -spherical(0.0))[0] == pytest.approx(math.pi)


def test_canonical_pairs_match_the_goniometer_convention() -> None:
    wi, wo = TABLE.directions()
    l_c, d_c = canonical_pairs(rotate_about_normal(wi, 1.3, True), rotate_about_normal(wo, 1.3,
                                                                                      True))
    oblique = TABLE.incidence_zenith_deg > 0.0
    np.testing.assert_allclose(l_c, wi, atol=1e-12)
    np.testing.assert_allclose(d_c[oblique], wo[oblique], atol=1e-12)
    # a zenith wi has no azimuth: wo goes into the xz plane (Δφ = 0)
    np.testing.assert_allclose(d_c[~oblique, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(d_c[~oblique, 0], np.hypot(wo[~oblique, 0], wo[~oblique, 1]))


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"u": 0.0}, "u"), ({"u": -1.0}, "u"), ({"u": math.inf}, "u"), ({"u": True}, "u"),
    ({"neighbours": 0}, "neighbours"), ({"neighbours": 2.5}, "neighbours"),
])
def test_bad_exponent_or_neighbourhood_is_refused(kwargs, field) -> None:
    wi = spherical(0.3)
    with pytest.raises(InvalidInputError) as err:
        idw_interpolate(TABLE, wi, wi, **kwargs)
    assert err.value.field == field


def test_empty_query_gives_an_empty_answer() -> None:
    assert idw_interpolate(TABLE, np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


# -------------------------------------------------------------------------------------------
# Edges, as properties
# -------------------------------------------------------------------------------------------
#: polar angles [rad] at the edges: zenith, tiny, grazing, tangent, below the horizon
EDGE_THETA = [0.0, 1e-300, 1e-9, math.radians(89.999), math.pi / 2, math.pi / 2 + 1e-9, 2.0]
theta = st.one_of(st.sampled_from(EDGE_THETA), st.floats(0.0, math.pi))
phi = st.floats(0.0, 2 * math.pi)


@settings(max_examples=200, deadline=None)
@given(theta, phi, theta, phi, st.sampled_from([1, 3, 16]))
def test_any_pair_of_directions_gives_a_finite_value_between_the_extremes(
    ti, pi, to, po, k
) -> None:
    wi, wo = spherical(ti, pi), spherical(to, po)
    value = idw_interpolate(TABLE, wi, wo, neighbours=k)[0]
    assert math.isfinite(value)  # a convex combination, up to rounding
    assert TABLE.brdf_per_sr.min() * (1 - 1e-12) <= value <= TABLE.brdf_per_sr.max() * (1 + 1e-12)


@settings(max_examples=100, deadline=None)
@given(theta, phi, st.floats(0.0, 1e3))
def test_coincident_directions_are_fine(t, p, value) -> None:
    w = spherical(t, p)
    table = GoniometerTable([10.0, 40.0], [10.0, 40.0], [0.0, 0.0], [value, 0.5 * value])
    got = idw_interpolate(table, w, w)[0]
    assert math.isfinite(got) and 0.5 * value * (1 - 1e-12) <= got <= value * (1 + 1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 89.9), st.floats(0.0, 89.9), st.floats(0.0, 180.0),
       st.floats(0.0, 1e6), theta, phi, theta, phi)
def test_a_table_of_one_row_is_that_value_everywhere(a, b, c, value, ti, pi, to, po) -> None:
    table = GoniometerTable([a], [b], [c], [value])
    got = idw_interpolate(table, spherical(ti, pi), spherical(to, po))[0]
    assert got == value


@settings(max_examples=50, deadline=None)
@given(theta, phi, theta, phi)
def test_a_table_of_zeros_is_zero_everywhere(ti, pi, to, po) -> None:
    table = TABLE.subset(np.ones(len(TABLE), bool))
    zeros = GoniometerTable(table.incidence_zenith_deg, table.reflection_zenith_deg,
                            table.azimuth_difference_deg, np.zeros(len(table)))
    assert idw_interpolate(zeros, spherical(ti, pi), spherical(to, po))[0] == 0.0


def test_zero_length_and_duplicate_inputs_do_not_give_nan() -> None:
    table = GoniometerTable([30.0, 30.0], [30.0, 30.0], [180.0, 180.0], [0.2, 0.4])
    wi, wo = table.directions()
    assert idw_interpolate(table, wi[:1], wo[:1])[0] == pytest.approx(0.3)  # mean at ρ'
    got = idw_interpolate(table, np.zeros((1, 3)), np.zeros((1, 3)))
    assert np.all(np.isfinite(got))


def test_exact_distance_is_tiny() -> None:
    assert EXACT_DISTANCE_RAD <= 1e-8
