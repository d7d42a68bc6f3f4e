"""Adaptive sampling: it reaches its target, its error estimate is honest, budgets hold."""

import time
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.adaptive import (
    noise_fraction,
    pixels_that_matter,
    range_standard_error_m,
    render_adaptive,
)
from sim_core.errors import InvalidInputError
from sim_core.render import LightField, RenderSettings
from sim_core.tof import ambiguity_range_m, phase_from_phasor, range_from_phase

F = 60.24e6
TARGET_M = 4e-3


#: the ``corner`` and its converged ``reference`` (tests/sim_core/conftest.py)
CORNER_WIDTH_PX = 40
REFERENCE_SPP, REFERENCE_SEED = 16384, 777


def ranges(lf):
    return range_from_phase(phase_from_phasor(lf.phasor[0]), F)


def test_every_pixel_that_matters_reaches_the_target(corner):
    res, rep = render_adaptive(corner, RenderSettings(max_bounces=3, seed=1),
                               target_range_error_m=TARGET_M)
    se = range_standard_error_m(res.light_field)[pixels_that_matter(res.light_field)]
    assert np.all(se <= TARGET_M)
    assert rep.achieved_range_error_mm <= TARGET_M * 1e3
    assert rep.fraction_meeting_target == 1.0
    # Pixels differ in how much multipath noise they carry, so they get different counts.
    assert rep.spp_max > 2 * rep.spp_min


def test_reported_error_agrees_with_the_real_error_over_several_seeds(corner, reference):
    u = ambiguity_range_m(F)
    ref_r = ranges(reference)
    ref_se = range_standard_error_m(reference)
    z2 = []
    for seed in (11, 12, 13):
        res, _ = render_adaptive(corner, RenderSettings(max_bounces=3, seed=seed),
                                 target_range_error_m=TARGET_M)
        lf = res.light_field
        m = pixels_that_matter(lf) & pixels_that_matter(reference)
        err = (ranges(lf) - ref_r + u / 2) % u - u / 2  # wrap-aware difference
        # The reference has its own (smaller) Monte Carlo error: add it in quadrature.
        sigma = np.sqrt(range_standard_error_m(lf) ** 2 + ref_se**2)
        z2.append(np.mean((err[m] / sigma[m]) ** 2))
    # z is about standard normal if the estimate is honest. Stopping as soon as a noisy estimate
    # dips below the target biases it low by a few per cent; more than 25 % would be a bug.
    rms_z = float(np.sqrt(np.mean(z2)))
    assert 0.8 < rms_z < 1.25, rms_z


def test_a_larger_time_budget_buys_a_smaller_error(corner):
    # Budgets of CPU seconds (this process's threads): other processes on a loaded machine do
    # not eat into them, so the outcome does not depend on the load. Wall time is the default.
    _, small = render_adaptive(corner, RenderSettings(max_bounces=3, seed=2),
                               time_budget_s=0.5, clock=time.process_time)
    _, big = render_adaptive(corner, RenderSettings(max_bounces=3, seed=2),
                             time_budget_s=3.0, clock=time.process_time)
    assert big.achieved_range_error_p95_mm < small.achieved_range_error_p95_mm
    # A round that is under way finishes, so the budget can be overrun by one round at most.
    assert small.seconds < 0.5 + 1.0 and big.seconds < 3.0 + 1.5


def test_same_seed_same_adaptive_result(corner):
    a, _ = render_adaptive(corner, RenderSettings(seed=5), target_range_error_m=2e-2)
    b, _ = render_adaptive(corner, RenderSettings(seed=5), target_range_error_m=2e-2)
    np.testing.assert_array_equal(a.light_field.phasor, b.light_field.phasor)
    np.testing.assert_array_equal(a.light_field.samples_per_pixel, b.light_field.samples_per_pixel)


@pytest.mark.parametrize(("kw", "field"), [
    ({}, "target_range_error_mm"),
    ({"target_range_error_m": -1e-3}, "target_range_error_mm"),
    ({"time_budget_s": 0.0}, "time_budget_s"),
])
def test_bad_adaptive_settings_name_the_field(corner, kw, field):
    with pytest.raises(InvalidInputError, match=field):
        render_adaptive(corner, RenderSettings(), **kw)


# -- the target as a fraction of the sensor's noise ----------------------------------------------
NOISE_FRACTION = 0.5


def _relative_amplitude_error(lf, ref):
    """(|phasor| - |reference|) / |reference| at the first frequency."""
    a, b = np.abs(lf.phasor[0]), np.abs(ref.phasor[0])
    return np.where(b > 0, (a - b) / np.where(b > 0, b, 1.0), 0.0)


@pytest.fixture(scope="module")
def to_half_the_noise(corner):
    return render_adaptive(corner, RenderSettings(max_bounces=3, seed=21), initial_spp=8,
                           target_noise_fraction=NOISE_FRACTION)


def test_the_noise_fraction_target_holds_against_a_reference(corner, reference,
                                                             to_half_the_noise):
    """Rendered to half the sensor's noise, the real Monte Carlo error (against a 16384-spp
    reference) of amplitude and phase is about half the sensor's predicted noise, not more."""
    from sim_core.sensor import mean_electrons, predicted_phase_std_rad

    res, rep = to_half_the_noise
    lf = res.light_field
    assert rep.target_noise_fraction == NOISE_FRACTION
    assert rep.fraction_meeting_target == 1.0
    assert rep.achieved_noise_fraction <= NOISE_FRACTION
    assert noise_fraction(lf, corner)[pixels_that_matter(lf)].max() <= NOISE_FRACTION
    e = mean_electrons(reference.dc_active, reference.dc_ambient, reference.phasor,
                       corner.camera, corner.sensor)
    sensor_rel = predicted_phase_std_rad(e, corner.sensor)
    m = pixels_that_matter(lf) & pixels_that_matter(reference) & np.isfinite(sensor_rel)
    amp = _relative_amplitude_error(lf, reference)[m] / sensor_rel[m]
    phase = np.angle(lf.phasor[0] * np.conj(reference.phasor[0]))[m] / sensor_rel[m]
    for name, z in (("amplitude", amp), ("phase", phase)):
        rms = float(np.sqrt(np.mean(z**2)))
        # Stopping when a noisy estimate dips below the target lets a few pixels end above it;
        # the RMS over the frame stays at or below the target (the reference adds ~0.02).
        assert rms <= 1.1 * NOISE_FRACTION, (name, rms)
    # Pixels get what they need: the corner's multipath is noisy against a quiet sensor.
    assert rep.spp_max > 2 * rep.spp_min >= 16


def test_a_larger_noise_fraction_needs_fewer_samples(corner, to_half_the_noise):
    _, loose = render_adaptive(corner, RenderSettings(max_bounces=3, seed=21), initial_spp=8,
                               target_noise_fraction=4 * NOISE_FRACTION)
    tight = to_half_the_noise[1]
    assert loose.spp_mean < tight.spp_mean / 8
    assert tight.achieved_noise_fraction <= NOISE_FRACTION < loose.achieved_noise_fraction


@pytest.mark.parametrize("bad", [0.0, -0.1, 11.0, float("nan")])
def test_a_bad_noise_fraction_names_the_field(corner, bad):
    with pytest.raises(InvalidInputError, match="target_noise_fraction"):
        render_adaptive(corner, RenderSettings(), target_noise_fraction=bad)


@settings(max_examples=60, deadline=None)
@given(
    magnitude=st.sampled_from([0.0, 5e-324, 1e-300, 1e-12, 1.0, 1e30]),
    variance=st.sampled_from([0.0, 5e-324, 1e-6, 1.0, 1e300]),
    samples=st.sampled_from([0, 1, 64]),
    ambient=st.sampled_from([0.0, 1e-9, 1e3]),
)
def test_noise_fraction_is_finite_or_inf_at_its_edges(corner, magnitude, variance, samples,
                                                      ambient):
    """Zero or subnormal phasors, zero or huge variance, no samples, bright sun: no NaN, no
    warning; 0 where the sensor sees no modulated light; never below 0 (inf where a pixel has
    no samples, or more noise than a float holds: it wants samples)."""
    h, w = corner.camera.intrinsics.height_px, corner.camera.intrinsics.width_px
    shape = (h, w)
    lf = LightField(
        frequencies_hz=np.array([F]),
        dc_active=np.full(shape, magnitude), dc_ambient=np.full(shape, ambient),
        phasor=np.full((1, *shape), magnitude * (0.6 + 0.8j)),
        truth_range_m=np.ones(shape), truth_depth_z_m=np.ones(shape),
        truth_normal=np.zeros((*shape, 3)), object_id=np.zeros(shape, dtype=np.int32),
        hit=np.ones(shape, dtype=bool), samples_per_pixel=np.full(shape, samples, np.int32),
        dc_active_var=np.full(shape, variance), dc_ambient_var=np.zeros(shape),
        phasor_cov=np.stack([np.full((1, *shape), variance), np.full((1, *shape), variance),
                             np.zeros((1, *shape))], axis=1),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frac = noise_fraction(lf, corner)
    assert not np.isnan(frac).any()
    assert (frac >= 0).all()
    if magnitude == 0.0:
        assert (frac == 0).all()
    if samples > 0 and variance <= 1.0 and magnitude >= 1e-12:
        assert np.isfinite(frac).all()
