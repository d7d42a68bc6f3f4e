"""Adaptive sampling: it reaches its target, its error estimate is honest, budgets hold."""

import numpy as np
import pytest

from sim_core.adaptive import pixels_that_matter, range_standard_error_m, render_adaptive
from sim_core.errors import InvalidInputError
from sim_core.render import RenderSettings, render
from sim_core.tof import ambiguity_range_m, phase_from_phasor, range_from_phase
from tests.sim_core.scenes import small_example

F = 60.24e6
TARGET_M = 4e-3


@pytest.fixture(scope="module")
def corner():
    return small_example("corner", width=40)


@pytest.fixture(scope="module")
def reference(corner):
    return render(corner, RenderSettings(spp=16384, max_bounces=3, seed=777)).light_field


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
    _, small = render_adaptive(corner, RenderSettings(max_bounces=3, seed=2),
                                       time_budget_s=0.5)
    _, big = render_adaptive(corner, RenderSettings(max_bounces=3, seed=2),
                                   time_budget_s=3.0)
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
