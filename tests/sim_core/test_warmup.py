"""The illumination's warm-up and its depth drift (issue 27): the curve, the phase, the frame."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from sim_core.twin_file import CameraTemperature, parse_reality
from sim_core.warmup import TemperatureDrift, illumination_temperature_c

WARM = CameraTemperature(illumination_start_c=25.0, illumination_end_c=45.0,
                         time_constant_s=600.0, depth_drift_mm_per_c=[0.5])
FREQS = (80.32e6, 60.24e6)


def test_the_illumination_warms_from_start_to_end_with_its_time_constant():
    assert illumination_temperature_c(0.0, WARM) == 25.0
    # One time constant: 1 - 1/e of the way.
    assert illumination_temperature_c(600.0, WARM) == pytest.approx(45.0 - 20.0 / np.e)
    assert illumination_temperature_c(1e9, WARM) == 45.0  # the exponential underflows to 0
    with pytest.raises(InvalidInputError, match="elapsed_s"):
        illumination_temperature_c(-1.0, WARM)
    with pytest.raises(InvalidInputError, match="elapsed_s"):
        illumination_temperature_c(float("nan"), WARM)


@settings(max_examples=60, deadline=None)
@given(t0=st.floats(-40, 125), t1=st.floats(-40, 125), tau=st.floats(1e-6, 1e6),
       t=st.floats(0, 1e12))
def test_the_temperature_stays_between_start_and_end(t0, t1, tau, t):
    spec = CameraTemperature(illumination_start_c=t0, illumination_end_c=t1,
                             time_constant_s=tau, depth_drift_mm_per_c=[0.1])
    temp = illumination_temperature_c(t, spec)
    assert min(t0, t1) - 1e-9 <= temp <= max(t0, t1) + 1e-9


def test_the_drift_is_the_range_change_as_a_phase_per_frequency():
    drift = TemperatureDrift.from_spec(WARM, FREQS)
    np.testing.assert_allclose(drift.range_drift_m(35.0), [0.005, 0.005])
    expect = [4 * np.pi * f * 0.005 / SPEED_OF_LIGHT_M_S for f in FREQS]
    np.testing.assert_allclose(drift.phase_offset_rad(35.0), expect)
    np.testing.assert_array_equal(drift.phase_offset_rad(25.0), [0.0, 0.0])
    per_f = TemperatureDrift.from_spec(
        WARM.model_copy(update={"depth_drift_mm_per_c": [0.2, 0.6]}), FREQS)
    np.testing.assert_allclose(per_f.range_drift_m(30.0), [0.001, 0.003])
    with pytest.raises(InvalidInputError, match="3 entries for 2 modulation frequencies"):
        TemperatureDrift.from_spec(
            WARM.model_copy(update={"depth_drift_mm_per_c": [0.1, 0.2, 0.3]}), FREQS)


@settings(max_examples=60, deadline=None)
@given(k=st.floats(-20, 20), temp=st.floats(-40, 125),
       re=st.floats(-1e6, 1e6), im=st.floats(-1e6, 1e6))
def test_the_drift_keeps_every_phasors_magnitude(k, temp, re, im):
    drift = TemperatureDrift.from_spec(
        WARM.model_copy(update={"depth_drift_mm_per_c": [k]}), FREQS)
    z = np.full((2, 3, 4), complex(re, im))
    out = drift.apply_to_phasor(z, temp)
    # A subnormal phasor (|z| < 2.2e-308) has fewer than 53 bits to keep: any rotation
    # of it rounds to the next representable step, so below that the check is absolute.
    np.testing.assert_allclose(np.abs(out), np.abs(z), rtol=1e-12, atol=1e-300)
    if re == 0.0 and im == 0.0:
        assert not np.any(out)  # a dark pixel stays dark


def wall_spec(width: int = 32) -> dict:
    scale = width / 224.0
    return {
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]},
                   "width_px": width, "height_px": round(171 * scale),
                   "fx_px": 208.33 * scale, "fy_px": 208.33 * scale},
        "illumination": {"power_w": 1.0},
        "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [20.0, 20.0]},
                     "material": {"kind": "lambertian", "params": {"albedo": 0.8}},
                     "pose": {"position_m": [0.0, 1.5, 0.0], "rotation_deg": [90, 0, 0]}}],
        "optics": {"diffraction": False, "pixel_aperture": False},
    }


def test_a_frame_at_a_warmer_temperature_reads_the_drift_farther():
    spec = parse_scene_spec(wall_spec())
    twin = parse_reality({"camera": {"temperature": WARM.model_dump()}})
    request = RenderRequest(RenderSettings(integrator="direct", spp=2, seed=3), effects="auto")
    cold = simulate(build_scene(spec, twin=twin, illumination_temperature_c=25.0), request)
    warm = simulate(build_scene(spec, twin=twin, illumination_temperature_c=41.0), request)
    assert not next(e for e in cold.plan.effects if e.name == "temperature_drift").enabled
    drift = next(e for e in warm.plan.effects if e.name == "temperature_drift")
    assert drift.enabled and drift.numbers["range_drift_mm"] == pytest.approx([8.0])
    both = cold.image.valid & warm.image.valid
    assert both.sum() > 100
    diff_mm = np.median(warm.image.range_m[both] - cold.image.range_m[both]) * 1e3
    assert diff_mm == pytest.approx(16 * 0.5, abs=0.3)  # 16 degC x 0.5 mm/degC
    with pytest.raises(InvalidInputError, match="illumination_temperature_c"):
        build_scene(spec, twin=twin, illumination_temperature_c=500.0)


def test_a_kept_sensor_light_exposes_the_same_frame_as_the_optics_run_again():
    """The world keeps each render's light on the sensor (MTF, stray light, the camera's phase
    errors) and exposes every frame from it at that frame's temperature: the same frame, bit
    for bit, as running the whole optics again."""
    from sim_core.pipeline import expose_light, render_light, sensor_light

    spec = parse_scene_spec(wall_spec())
    twin = parse_reality({"camera": {
        "temperature": WARM.model_dump(),
        "stray_light": {"fraction": 0.05, "kernel_radius_px": 12.0},
        "depth": {"phase_offset_rad": [0.01],
                  "wiggling": [{"harmonic": 4, "amplitude_rad": 0.02, "phase_rad": 0.4}]}}})
    scene = build_scene(spec, twin=twin)
    rendered = render_light(scene, RenderRequest(RenderSettings(integrator="direct", spp=2,
                                                                seed=3), effects="all"))
    kept = sensor_light(scene, rendered.plan, rendered.light_field, ideal=False)
    for temperature_c in (25.0, 38.5):
        warm = build_scene(spec, twin=twin, illumination_temperature_c=temperature_c)
        again = expose_light(warm, rendered, noise_rng=np.random.default_rng(9))
        from_kept = expose_light(warm, rendered, noise_rng=np.random.default_rng(9), light=kept)
        np.testing.assert_array_equal(from_kept.raw.phase_images, again.raw.phase_images)
        np.testing.assert_array_equal(from_kept.raw.intensity, again.raw.intensity)
    # an ideal exposure never takes a light with the camera's phase errors in it
    ideal = expose_light(scene, rendered, ideal=True, light=kept)
    np.testing.assert_array_equal(ideal.image.range_m,
                                  expose_light(scene, rendered, ideal=True).image.range_m)
