"""Hard cases through the whole chain: extreme ambient light and targets at awkward ranges."""

import dataclasses

import numpy as np
import pytest

from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from sim_core.tof import ambiguity_range_m

SETTINGS = RenderSettings(integrator="direct", spp=2, seed=9)


def wall_scene(distance_m: float, **extra):
    spec = {
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]},
                   "width_px": 32, "height_px": 24, "fx_px": 30.0, "fy_px": 30.0},
        "illumination": {"power_w": 5.0},
        "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [400, 400]},
                     "material": {"kind": "lambertian", "params": {"albedo": 0.8}},
                     "pose": {"position_m": [0, distance_m, 0], "rotation_deg": [90, 0, 0]}}],
        **extra,
    }
    return build_scene(parse_scene_spec(spec))


def test_one_hundred_suns_push_every_lit_pixel_into_the_sbi_limit():
    # The Sun at 0.1 AU: 100 x its in-band irradiance at the Earth.
    sun = {"ambient": {"sun": {"direction": [0.0, 1.0, 0.0], "distance_m": 1.495978707e10}}}
    frame = simulate(wall_scene(2.0, **sun), RenderRequest(SETTINGS))
    raw = frame.raw
    assert raw.sbi_limit.all()
    assert not frame.image.valid.any()
    for arr in (raw.phase_images, raw.intensity, frame.image.amplitude, frame.image.intensity):
        assert np.isfinite(arr).all()
    assert np.isnan(frame.image.range_m).all()


@pytest.mark.parametrize("fraction", [0.0, 0.999999])
def test_target_at_the_ambiguity_range_wraps_without_nan(fraction):
    u = ambiguity_range_m(60.24e6)
    exact = dataclasses.replace(SETTINGS, jitter=False)
    no_mtf = {"optics": {"diffraction": False, "pixel_aperture": False}}
    scene = wall_scene(u * (1 + fraction) if fraction else u, **no_mtf)
    frame = simulate(scene, RenderRequest(exact, ideal=True))
    img, truth = frame.image, frame.light_field.truth_range_m
    assert img.valid.all() and np.isfinite(img.range_m).all()
    assert np.all((img.range_m >= 0.0) & (img.range_m < u))
    # Ranges wrap at c / 2f: compare on the circle of circumference u.
    d = np.abs(img.range_m - np.mod(truth, u))
    assert np.minimum(d, u - d).max() < 1e-5


@pytest.mark.parametrize("distance_m", [1e-3, 1e4])
def test_targets_at_one_millimetre_and_ten_kilometres_stay_finite(distance_m):
    frame = simulate(wall_scene(distance_m), RenderRequest(SETTINGS))
    img = frame.image
    assert np.isfinite(img.amplitude).all() and np.isfinite(img.intensity).all()
    assert np.all(np.isnan(img.range_m[~img.valid]))
    if distance_m > 1.0:  # 10 km: far too little light for a valid pixel
        assert not img.valid.any()
    else:  # 1 mm: the source saturates the sensor (SBI limit or full well)
        assert frame.raw.saturated.any() or frame.raw.sbi_limit.any()


def test_empty_scene_is_all_invalid():
    spec = {"camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0]},
                       "width_px": 16, "height_px": 12, "fx_px": 15.0, "fy_px": 15.0}}
    frame = simulate(build_scene(parse_scene_spec(spec)), RenderRequest(SETTINGS))
    assert not frame.image.valid.any()
    assert frame.rays_traced > 0 and np.isfinite(frame.image.amplitude).all()
