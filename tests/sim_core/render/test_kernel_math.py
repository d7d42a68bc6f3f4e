"""The hand-written maths of the render kernels: sine/cosine in turns and the source profile."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numba import njit

from sim_core.lights import PointLight
from sim_core.materials.kernels import sincos_turns
from sim_core.render.kernels import _profile_intensity


@njit
def _sincos(t):
    out = np.empty((t.shape[0], 2))
    for i in range(t.shape[0]):
        out[i, 0], out[i, 1] = sincos_turns(t[i])
    return out


@njit
def _profile(cos_a, scale, angle, rel):
    out = np.empty(cos_a.shape[0])
    for i in range(cos_a.shape[0]):
        out[i] = _profile_intensity(cos_a[i], scale, angle, rel)
    return out


def test_sincos_turns_is_accurate_to_a_few_ulp_over_a_turn():
    t = np.concatenate([np.linspace(-0.5, 0.5, 200_001), np.random.default_rng(0).random(10**5)])
    got = _sincos(t)
    # math.sin(2 pi t) for |t| <= 1 rounds 2 pi t with an error below 7e-16.
    assert np.abs(got[:, 0] - np.sin(2 * np.pi * t)).max() < 1.5e-15
    assert np.abs(got[:, 1] - np.cos(2 * np.pi * t)).max() < 1.5e-15


def test_sincos_turns_is_exact_at_the_quarter_turns():
    t = np.array([0.0, 0.25, 0.5, 0.75, 1.0, -0.25, -0.5, 3.0, 1e6 + 0.25, -(2.0**40) - 0.75,
                  2.0**52 + 1, 1e19, -1e300])  # the last three: whole numbers of turns
    got = _sincos(t)
    want = np.array([[0, 1], [1, 0], [0, -1], [-1, 0], [0, 1], [-1, 0], [0, -1], [0, 1],
                     [1, 0], [1, 0], [0, 1], [0, 1], [0, 1]], dtype=float)
    np.testing.assert_array_equal(np.abs(got - want), 0.0)


@given(
    k=st.integers(min_value=-(2**30), max_value=2**30),
    r=st.integers(min_value=-(2**20), max_value=2**20),
)
def test_whole_turns_change_nothing(k, r):
    """A long path (many turns) keeps the precision of a short one: reduction is exact."""
    frac = r / 2.0**21  # exactly representable, so k + frac is too
    got = _sincos(np.array([k + frac, frac]))
    np.testing.assert_array_equal(got[0], got[1])


@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False))
def test_sincos_turns_stays_on_the_unit_circle(t):
    s, c = _sincos(np.array([t]))[0]
    assert abs(s) <= 1.0 and abs(c) <= 1.0
    assert s * s + c * c == pytest.approx(1.0, abs=1e-15)  # a few ulp, the check rounds too


def _light(angles_deg, rel):
    return PointLight(position_m=np.zeros(3), axis=np.array([0.0, 0.0, 1.0]), power_w=1.0,
                      profile_angle_rad=np.radians(angles_deg), profile_relative=np.array(rel))


def test_profile_matches_np_interp_zero_at_and_beyond_the_last_angle():
    light = _light([0, 20, 30, 38, 45, 60], [1.0, 0.95, 0.7, 0.3, 0.05, 0.0])
    angle = np.radians(np.concatenate([np.linspace(0.0, 90.0, 9001), [0, 20, 30, 38, 45]]))
    got = _profile(np.cos(angle), light.scale_w_sr, light.profile_angle_rad,
                   light.profile_relative)
    # the kernel sees the angle through its cosine: compare at the angle it recovers
    seen = np.arccos(np.cos(angle))
    want = light.scale_w_sr * np.interp(seen, light.profile_angle_rad, light.profile_relative)
    want[seen >= light.profile_angle_rad[-1]] = 0.0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)


def test_profile_edges_isotropic_first_angle_and_rounding_past_one():
    light = _light([5, 40], [0.5, 1.0])
    a, r = light.profile_angle_rad, light.profile_relative
    got = _profile(np.array([1.0 + 1e-15, 1.0, math.cos(math.radians(40.0)), -1.0]), 2.0, a, r)
    np.testing.assert_array_equal(got, [1.0, 1.0, 0.0, 0.0])  # below 5 deg: the first value
    iso = _profile(np.array([1.0, 0.0, -1.0]), 3.0, np.zeros(0), np.zeros(0))
    np.testing.assert_array_equal(iso, 3.0)


def test_sincos_turns_of_a_non_finite_angle_is_nan():
    assert np.isnan(_sincos(np.array([np.nan, np.inf, -np.inf]))).all()
