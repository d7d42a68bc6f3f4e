"""The PMD pixel model for any input: Poisson draws from 0 to 1e12 electrons, raw frames from
any non-negative electrons, and saturation hidden behind the SBI compensation.

(The whole chain at 100 suns, 1 mm and 10 km is in test_sensor_extremes.py. The pixel model at
nominal inputs, against closed forms, including exact ranges up to n_SBI,start, is in
tests/sim_core/test_sensor.py; this suite keeps to extreme inputs and properties of any input.)
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sim_core.camera import F_60_24_MHZ
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.noise import NORMAL_APPROX_MEAN, clipped_normal_mean, safe_poisson
from sim_core.raw import reconstruct_raw
from sim_core.sensor import PixelElectrons, SensorParams, expose
from tests.hard_cases.helpers import build, camera

N_DRAWS = 40_000


@pytest.fixture(scope="module")
def cam():
    return build(camera((0, 0, 0), (0, 1, 0)), []).camera


# -------------------------------------------------------------------------------------------
# safe_poisson from 0 to 1e12
# -------------------------------------------------------------------------------------------
MEANS = [0.0, 5e-324, 1e-300, 1e-6, 0.5, 1.0, 10.0, 1e3, 1e6,
         NORMAL_APPROX_MEAN * (1.0 - 1e-9), NORMAL_APPROX_MEAN, NORMAL_APPROX_MEAN * (1.0 + 1e-9),
         1e9, 1e12]


@pytest.mark.parametrize("mean", MEANS)
def test_safe_poisson_has_the_poisson_mean_and_variance_across_the_range(mean):
    draws = safe_poisson(np.random.default_rng(1), np.full(N_DRAWS, mean))
    assert draws.dtype == np.float64 and draws.shape == (N_DRAWS,)
    assert np.all(np.isfinite(draws)) and np.all(draws >= 0.0)
    if mean <= NORMAL_APPROX_MEAN:
        np.testing.assert_array_equal(draws, np.round(draws))  # counts
    # Mean within 5 standard errors, variance within 5 standard errors of the sample variance
    # of a Poisson variable, var(s^2) = (m + 2 m^2) / n.
    assert abs(draws.mean() - mean) <= 5.0 * math.sqrt(mean / N_DRAWS) + 1e-12
    assert abs(draws.var(ddof=1) - mean) <= 5.0 * math.sqrt((mean + 2 * mean**2) / N_DRAWS) + 1e-12


def test_safe_poisson_switch_to_the_normal_approximation_is_continuous():
    # Just below and just above the switch the draws must be the same distribution: compare
    # their quantiles (Poisson at 1e7 has skewness 3e-4, invisible at this sample size).
    below = safe_poisson(np.random.default_rng(2), np.full(N_DRAWS, NORMAL_APPROX_MEAN))
    above = safe_poisson(np.random.default_rng(3),
                         np.full(N_DRAWS, np.nextafter(NORMAL_APPROX_MEAN, np.inf)))
    sd = math.sqrt(NORMAL_APPROX_MEAN)
    q = [0.01, 0.1, 0.5, 0.9, 0.99]
    np.testing.assert_allclose(np.quantile(below, q), np.quantile(above, q), atol=0.1 * sd)
    assert abs(below.mean() - above.mean()) < 5.0 * sd * math.sqrt(2.0 / N_DRAWS)


@pytest.mark.parametrize("mean", [np.inf, -np.inf, np.nan])
def test_safe_poisson_rejects_non_finite_means(mean):
    with pytest.raises(ValueError, match="finite"):
        safe_poisson(np.random.default_rng(0), np.array([1.0, mean]))


@settings(max_examples=60, deadline=None)
@given(means=hnp.arrays(np.float64, st.integers(1, 20),
                        elements=st.floats(-1e12, 1e12) | st.sampled_from([0.0, -0.0, 1e7])),
       seed=st.integers(0, 2**32 - 1))
def test_safe_poisson_of_any_finite_mean_is_finite_nonnegative_and_zero_for_no_light(means, seed):
    draws = safe_poisson(np.random.default_rng(seed), means)
    assert draws.shape == means.shape
    assert np.all(np.isfinite(draws)) and np.all(draws >= 0.0)
    assert np.all(draws[means <= 0.0] == 0.0)


# -------------------------------------------------------------------------------------------
# Any non-negative electrons give a finite, bounded raw frame
# -------------------------------------------------------------------------------------------
electron_counts = st.floats(0.0, 1e15) | st.sampled_from([0.0, 5e-324, 36_500.0, 1e5, 5e5])



@settings(max_examples=200, deadline=None)
@given(mean=st.floats(-1e12, 1e12), std=st.one_of(st.just(0.0), st.floats(1e-300, 1e12)))
def test_the_clipped_readouts_mean_is_finite_and_bounded_at_every_edge(mean, std):
    m = float(clipped_normal_mean(np.array(mean), np.array(std)))
    assert math.isfinite(m)
    # never below the charge or 0, never above either by more than the noise's own mean |X|
    assert m >= max(mean, 0.0) * (1 - 1e-12)
    assert m <= max(mean, 0.0) + std / math.sqrt(2 * math.pi) * (1 + 1e-9) + 1e-300


@pytest.mark.parametrize(("mean", "std"), [(0.0, 1.0), (1.5, 2.0), (-3.0, 2.0), (40.0, 48.0)])
def test_the_clipped_readouts_mean_is_the_sampled_one(mean, std):
    x = np.random.default_rng(1).normal(mean, std, 1_000_000)
    assert float(clipped_normal_mean(np.array(mean), np.array(std))) == pytest.approx(
        np.maximum(x, 0.0).mean(), abs=4 * std / 1000)
    assert float(clipped_normal_mean(np.array(0.0), np.array(std))) == pytest.approx(
        std / math.sqrt(2 * math.pi), rel=1e-12)


@pytest.mark.parametrize("std", [-1.0, math.inf, math.nan])
def test_the_clipped_readouts_mean_refuses_a_bad_noise(std):
    with pytest.raises(ValueError, match="standard deviations"):
        clipped_normal_mean(np.array(1.0), np.array(std))

@st.composite
def pixel_electrons(draw) -> PixelElectrons:
    shape = (draw(st.integers(1, 3)), draw(st.integers(1, 4)))
    active = draw(hnp.arrays(np.float64, shape, elements=electron_counts))
    ambient = draw(hnp.arrays(np.float64, shape, elements=electron_counts))
    # The phasor's magnitude never exceeds the DC (|sum w e^{i phi}| <= sum w).
    frac = draw(hnp.arrays(np.float64, shape, elements=st.floats(0.0, 1.0)))
    phase = draw(hnp.arrays(np.float64, shape, elements=st.floats(0.0, 2 * np.pi)))
    phasor = (active * frac * np.exp(-1j * phase))[None]
    return PixelElectrons(active, ambient, draw(st.floats(0.0, 1e9)), phasor)


sensors = st.builds(
    SensorParams,
    read_noise_e=st.sampled_from([0.0, 25.0, 1e5]),
    adc_bits=st.integers(1, 24),
    adc_gain_e_per_dn=st.sampled_from([1e-3, 1.0, 25.0, 1e6]),
    full_well_e=st.sampled_from([1.0, 1e5, 1e9]),
    sbi_enabled=st.booleans(),
    sbi_limit_e=st.sampled_from([0.0, 5e5, 1e12]),
    demodulation_contrast=st.sampled_from([0.0, 0.8, 1.0]),
)


@settings(max_examples=80, deadline=None)
@given(e=pixel_electrons(), sensor=sensors, noise=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_any_nonnegative_electrons_give_a_finite_bounded_raw_frame(e, sensor, noise, seed, cam):
    rng = np.random.default_rng(seed) if noise else None
    raw = expose(e, cam, sensor, rng)
    top = 2.0**sensor.adc_bits - 1.0
    assert np.all(np.isfinite(raw.taps)) and np.all((raw.taps >= 0.0) & (raw.taps <= top))
    assert np.all(np.isfinite(raw.phase_images)) and np.all(np.abs(raw.phase_images) <= top)
    # intensity: the mean tap sum A + B over the phase steps
    assert np.all(np.isfinite(raw.intensity)) and np.all(
        (raw.intensity >= 0.0) & (raw.intensity <= 2.0 * top * (1 + 1e-6)))
    assert raw.saturated.shape == raw.sbi_limit.shape == e.active.shape
    img = reconstruct_raw(raw, np.ones(e.active.shape))
    assert np.all(np.isfinite(img.amplitude)) and np.all(img.amplitude >= 0.0)
    assert np.all((img.phase_rad >= 0.0) & (img.phase_rad < 2 * np.pi))
    assert np.all(np.isfinite(img.range_m[img.valid]))
    assert not np.any(img.valid & (raw.saturated | raw.sbi_limit))


@settings(max_examples=60, deadline=None)
@given(e=pixel_electrons(), seed=st.integers(0, 2**32 - 1), rel=st.floats(-1e-9, 1e-9))
def test_raw_frame_is_stable_under_a_1e_9_change_of_the_electrons(e, seed, rel, cam):
    # Same seed, electrons 1e-9 relative apart: Poisson counts and rounding move by at most a
    # step where a draw lands on an edge, so a correlation image moves by at most 2 DN (both
    # taps) and the mean over the frame by far less. A rejection sampler that consumed a
    # different number of uniforms would shift every later draw: that is not the case.
    sensor = SensorParams()
    scaled = PixelElectrons(e.active * (1 + rel), e.ambient * (1 + rel), e.dark * (1 + rel),
                            e.phasor * (1 + rel))
    a = expose(e, cam, sensor, np.random.default_rng(seed))
    b = expose(scaled, cam, sensor, np.random.default_rng(seed))
    d = np.abs(a.phase_images - b.phase_images)
    assert d.max() <= 2.0
    assert d.mean() <= 0.25


# -------------------------------------------------------------------------------------------
# Saturation behind the SBI compensation
# -------------------------------------------------------------------------------------------
RANGES_M = np.linspace(0.1, 2.4, 12)[None]


def bright_electrons(active_e: float) -> PixelElectrons:
    phase = 4.0 * np.pi * F_60_24_MHZ * RANGES_M / SPEED_OF_LIGHT_M_S
    shape = RANGES_M.shape
    return PixelElectrons(np.full(shape, active_e), np.zeros(shape), 1.0,
                          (active_e * np.exp(-1j * phase))[None])


@pytest.mark.parametrize("active_e", [5e4, 8e4, 1.2e5, 3e5])
def test_modulated_signal_beyond_the_sbi_range_is_flagged_or_exact(active_e, cam):
    # The taps differ by D N cos(tau + phi): beyond n_SBI,start the compensation cannot keep
    # both taps in range. Either the difference survives (the range is exact) or the pixel
    # must be reported invalid; never a valid pixel with a wrong range.
    raw = expose(bright_electrons(active_e), cam, SensorParams(read_noise_e=0.0), None)
    img = reconstruct_raw(raw, np.ones(RANGES_M.shape))
    err = np.abs(img.range_m - RANGES_M)
    assert np.all(err[img.valid] < 1e-3)
    assert np.all(raw.saturated[~img.valid] | raw.sbi_limit[~img.valid])
