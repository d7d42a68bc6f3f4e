"""Sub-frame timing: when each raw sub-frame is exposed, and a frame taken while the table turns."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError
from sim_core.pipeline import (
    demodulated_phasor,
    expose_light,
    render_in_motion,
    render_light,
    simulate,
    simulate_in_motion,
)
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.sensor import PixelElectrons, SensorParams, tap_means
from sim_core.subframes import (
    MOTION_TOLERANCE_DEG,
    READOUT_S,
    moves_during_frame,
    phase_step_angles_deg,
    phase_step_times_s,
    subframe_times_s,
)
from tests.sim_core.scenes import small_example

REQUEST = RenderRequest(RenderSettings(integrator="direct", spp=2, seed=3), effects="all")


def test_sub_frames_are_exposed_at_k_times_exposure_plus_readout():
    # MODE_5_45FPS_500: grey + 4 phases; MODE_9_5FPS_2000: grey + 4 at 80.32 + 4 at 60.24 MHz
    assert subframe_times_s(1, 500e-6).shape == (5,)
    nine = subframe_times_s(2, 2000e-6)
    np.testing.assert_allclose(nine, np.arange(9) * (2000e-6 + READOUT_S))
    steps = phase_step_times_s(2, 2000e-6)
    assert steps.shape == (2, 4)
    assert steps[0, 0] == nine[1] and steps[1, 3] == nine[8]  # grey first, then by frequency


@pytest.mark.parametrize(("kw", "field"), [
    ({"n_frequencies": 0}, "n_frequencies"),
    ({"n_frequencies": 5}, "n_frequencies"),
    ({"exposure_s": -1e-6}, "exposure_s"),
    ({"exposure_s": float("nan")}, "exposure_s"),
    ({"readout_s": 2.0}, "readout_s"),
])
def test_bad_timing_inputs_are_refused_naming_the_field(kw, field):
    args = {"n_frequencies": 1, "exposure_s": 500e-6, **kw}
    with pytest.raises(InvalidInputError) as err:
        subframe_times_s(**args)
    assert err.value.field == field and "allowed" in str(err.value)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 4), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_sub_frame_times_are_finite_increasing_and_start_at_zero(n_f, exposure_s, readout_s):
    t = subframe_times_s(n_f, exposure_s, readout_s)
    assert t.shape == (1 + 4 * n_f,) and t[0] == 0.0 and np.all(np.isfinite(t))
    assert np.all(np.diff(t) >= 0.0)


def test_phase_step_angles_follow_the_motion_and_the_tolerance_decides_a_render_per_step():
    turning = phase_step_angles_deg(lambda dt: 30.0 + 10.0 * dt, 1, 500e-6)
    np.testing.assert_allclose(turning, 30.0 + 10.0 * phase_step_times_s(1, 500e-6))
    assert moves_during_frame(turning)  # 10 deg/s over 4.5 ms: 0.045 deg
    still = phase_step_angles_deg(lambda dt: 30.0 + 1e-3 * math.sin(dt), 1, 500e-6)
    assert not moves_during_frame(still)
    assert not moves_during_frame(np.array([0.0, 0.5 * MOTION_TOLERANCE_DEG]))
    with pytest.raises(InvalidInputError, match="angles_deg"):
        moves_during_frame(np.array([0.0, np.nan]))


def test_equal_steps_give_the_static_taps_and_phasor():
    rng = np.random.default_rng(1)
    phasor = (rng.random((2, 3, 4)) + 1j * rng.random((2, 3, 4))) * 100
    active, ambient = rng.random((3, 4)) * 500, rng.random((3, 4)) * 50
    sensor = SensorParams()
    static = tap_means(PixelElectrons(active, ambient, 3.0, phasor), sensor)
    per_step = PixelElectrons(np.broadcast_to(active, (2, 4, 3, 4)),
                              np.broadcast_to(ambient, (2, 4, 3, 4)), 3.0,
                              np.repeat(phasor[:, None], 4, axis=1))
    for a, b in zip(static, tap_means(per_step, sensor), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12)
    np.testing.assert_allclose(demodulated_phasor(np.repeat(phasor[:, None], 4, axis=1)), phasor)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.complex_numbers(max_magnitude=1e6, allow_nan=False, allow_infinity=False),
                min_size=4, max_size=4))
def test_the_demodulated_phasor_is_finite_and_bounded_by_its_steps(steps):
    p = np.array(steps).reshape(1, 4, 1, 1)
    z = demodulated_phasor(p)
    assert np.all(np.isfinite(z))
    # each C_i is bounded by |p_i|, so |Z / 2| <= (sum of the four magnitudes) / 2
    assert abs(z[0, 0, 0]) <= 0.5 * np.abs(p).sum() + 1e-9


def _scene_at(angle_deg):
    return small_example("satellite_ground_test", width=40, turntable_deg=angle_deg)


def test_a_table_that_does_not_move_is_rendered_once_and_as_before():
    angles = np.full((1, 4), 20.0) + np.array([0.0, 2e-4, 4e-4, 6e-4])
    _scene, light = render_in_motion(_scene_at, angles, REQUEST)
    assert not isinstance(light, list)  # one render
    moving = simulate_in_motion(_scene_at, angles, REQUEST, np.random.default_rng(5))
    static = simulate(_scene_at(20.0), REQUEST, noise_rng=np.random.default_rng(5))
    np.testing.assert_array_equal(moving.raw.phase_images, static.raw.phase_images)


def test_a_frame_taken_while_turning_smears_the_phases_at_edges_only():
    # 1000 deg/s with MODE_5_45FPS_500's timing: the four steps 1.5 deg apart (a small
    # image's pixels are 27 mm wide at the satellite: the edges must move that far)
    angles = 20.0 + 1000.0 * phase_step_times_s(1, 500e-6)
    scene, steps = render_in_motion(_scene_at, angles, REQUEST)
    assert isinstance(steps, list) and len(steps) == 4
    moving = expose_light(scene, steps[0], ideal=True, steps=steps)
    assert moving.extra["subframes_rendered"] == 4
    images = [expose_light(_scene_at(float(a)), s, ideal=True).image
              for a, s in zip(angles.ravel(), steps, strict=True)]
    per_step = [im.range_m for im in images]
    spread_m = np.nanmax(per_step, axis=0) - np.nanmin(per_step, axis=0)
    amplitudes = [im.amplitude for im in images]
    amp_spread = np.ptp(amplitudes, axis=0) / np.maximum(np.max(amplitudes, axis=0), 1e-300)
    still = (spread_m < 1e-5) & (amp_spread < 1e-6)  # every step sees the same light here
    np.testing.assert_allclose(moving.image.range_m[still], per_step[0][still], atol=1e-4)
    edge = spread_m > 0.05  # the steps see different surfaces (an edge moved over the pixel)
    assert edge.sum() > 0
    off_m = np.abs(moving.image.range_m[edge] - per_step[0][edge])
    assert np.nanmax(off_m) > 0.01  # mixed phases: neither surface's depth


def test_the_raw_frame_of_a_turning_table_differs_from_a_static_one():
    angles = 20.0 + 100.0 * phase_step_times_s(1, 500e-6)
    moving = simulate_in_motion(_scene_at, angles, REQUEST, np.random.default_rng(5))
    assert moving.raw.meta["subframes"] is True
    first = render_light(_scene_at(20.0), REQUEST)
    static = expose_light(_scene_at(20.0), first, noise_rng=np.random.default_rng(5))
    assert not np.array_equal(moving.raw.phase_images, static.raw.phase_images)
