import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.tof import (
    ambiguity_range_m,
    common_frequency_hz,
    phase_from_phasor,
    range_from_phase,
    reconstruct,
    unwrap_two_frequencies,
)

F1, F2 = 80.32e6, 60.24e6


def phasor_at(range_m, f):
    return np.exp(-1j * 4.0 * np.pi * f * np.asarray(range_m) / SPEED_OF_LIGHT_M_S)


def test_phase_is_in_zero_two_pi_for_every_quadrant():
    angles = np.linspace(-4 * np.pi, 4 * np.pi, 1001)
    phi = phase_from_phasor(np.exp(-1j * angles))
    assert np.all((phi >= 0.0) & (phi < 2 * np.pi))
    np.testing.assert_allclose(np.exp(1j * phi), np.exp(1j * angles), atol=1e-12)


def test_phase_exactly_zero_and_two_pi_fold_to_zero():
    phi = phase_from_phasor(np.array([1.0 + 0j, np.exp(-2j * np.pi), 1.0 - 1e-18j, 1.0 + 1e-18j]))
    assert np.all(phi < 2 * np.pi)
    np.testing.assert_allclose(phi, 0.0, atol=1e-15)


def test_zero_phasor_gives_phase_zero_not_nan():
    assert phase_from_phasor(np.array([0j]))[0] == 0.0


def test_range_from_phase_is_seed_eq_7():
    assert range_from_phase(np.pi, 60.24e6) == pytest.approx(SPEED_OF_LIGHT_M_S / (4 * 60.24e6))


def test_common_frequency_of_the_dual_mode_is_20_08_mhz():
    assert common_frequency_hz(F1, F2) == pytest.approx(20.08e6)
    assert ambiguity_range_m(20.08e6) == pytest.approx(7.4649, abs=1e-4)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 7.46))
def test_two_frequency_unwrapping_recovers_range_beyond_single_ambiguity(r):
    p1 = phase_from_phasor(phasor_at([r], F1))
    p2 = phase_from_phasor(phasor_at([r], F2))
    got = unwrap_two_frequencies(p1, F1, p2, F2)[0]
    u_ext = ambiguity_range_m(20.08e6)
    err = min(abs(got - r), abs(got - r + u_ext), abs(got - r - u_ext))
    assert err < 1e-6


def test_target_at_exactly_the_ambiguity_range_reads_zero_without_nan():
    u = ambiguity_range_m(60.24e6)
    img = reconstruct(phasor_at([[u]], 60.24e6)[None], np.ones((1, 1)), np.array([60.24e6]),
                      np.ones((1, 1)), np.ones((1, 1), bool))
    assert np.isfinite(img.range_m).all()
    assert min(img.range_m[0, 0], u - img.range_m[0, 0]) < 1e-9


def test_invalid_pixels_get_nan_range_and_depth():
    ph = phasor_at(np.array([[1.0, 2.0]]), 60.24e6)[None]
    img = reconstruct(ph, np.ones((1, 2)), np.array([60.24e6]), np.full((1, 2), 0.5),
                      np.array([[True, False]]))
    assert img.range_m[0, 0] == pytest.approx(1.0)
    assert img.depth_z_m[0, 0] == pytest.approx(0.5)
    assert np.isnan(img.range_m[0, 1]) and np.isnan(img.depth_z_m[0, 1])
    assert not img.valid[0, 1]
