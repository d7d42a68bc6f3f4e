"""Stray light (issue 27): energy kept, border safe, dark pixels pulled towards bright ones."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sim_core.optics import StrayLight
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from sim_core.twin_file import parse_reality

images = arrays(np.float64, st.tuples(st.integers(1, 12), st.integers(1, 12)),
                elements=st.floats(0.0, 1e6))
radii = st.one_of(st.just(0.0), st.floats(1e-300, 1e-3), st.floats(1e-3, 1e4), st.just(1e4))


@settings(max_examples=80, deadline=None)
@given(image=images, fraction=st.floats(0.0, 1.0), radius=radii)
def test_stray_light_keeps_the_images_light_and_stays_finite_and_positive(image, fraction,
                                                                          radius):
    out = StrayLight(fraction, radius).apply(image)
    assert out.shape == image.shape and np.all(np.isfinite(out))
    assert np.all(out >= -1e-9 * max(1.0, image.max()))
    assert out.sum() == pytest.approx(image.sum(), rel=1e-9, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(fraction=st.floats(0.0, 1.0), radius=radii, seed=st.integers(0, 2**16))
def test_stray_light_is_linear_on_phasors(fraction, radius, seed):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(2, 5, 7)) + 1j * rng.normal(size=(2, 5, 7))
    s = StrayLight(fraction, radius)
    out = s.apply(z)
    np.testing.assert_allclose(out.real, s.apply(z.real), atol=1e-12)
    np.testing.assert_allclose(out.imag, s.apply(z.imag), atol=1e-12)
    np.testing.assert_allclose(out.sum(axis=(-2, -1)), z.sum(axis=(-2, -1)), atol=1e-9)


def test_edges_of_the_parameters():
    img = np.zeros((171, 224))
    img[80:90, 100:110] = 1.0
    assert StrayLight(0.0, 40.0).apply(img) is img  # fraction 0: nothing to do
    np.testing.assert_array_equal(StrayLight(0.3, 0.0).apply(img), img)  # radius 0: stays put
    dark = np.zeros((171, 224))
    np.testing.assert_array_equal(StrayLight(0.02, 40.0).apply(dark), dark)
    # A huge radius spreads the fraction uniformly over the image.
    flat = StrayLight(0.02, 1e4).apply(img)
    np.testing.assert_allclose(flat[0, 0], 0.02 * img.sum() / img.size, rtol=1e-3)
    # A bright patch's stray light falls off with distance with the kernel's radius.
    s = StrayLight(0.02, 20.0).apply(img)
    assert s[85, 130] > s[85, 150] > s[85, 200] > 0.0
    with pytest.raises(ValueError, match="fraction"):
        StrayLight(1.5, 3.0)
    with pytest.raises(ValueError, match="radius_px"):
        StrayLight(0.1, float("inf"))


def test_stray_light_pulls_a_dark_pixels_range_towards_a_bright_one():
    """A dark far wall beside a bright near panel: its range moves towards the panel's."""
    near = {"name": "panel", "mesh": {"kind": "rectangle", "size_m": [0.5, 2.0]},
            "material": {"kind": "lambertian", "params": {"albedo": 0.9}},
            "pose": {"position_m": [-0.3, 0.8, 0.0], "rotation_deg": [90, 0, 0]}}
    far = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [20.0, 20.0]},
           "material": {"kind": "lambertian", "params": {"albedo": 0.05}},
           "pose": {"position_m": [0.0, 1.6, 0.0], "rotation_deg": [90, 0, 0]}}
    spec = parse_scene_spec({
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]},
                   "width_px": 48, "height_px": 37, "fx_px": 44.6, "fy_px": 44.6},
        "illumination": {"power_w": 1.0}, "objects": [near, far],
        "optics": {"diffraction": False, "pixel_aperture": False}})
    request = RenderRequest(RenderSettings(integrator="direct", spp=2, seed=1), effects="auto",
                            ideal=True)
    clean = simulate(build_scene(spec), request)
    twin = parse_reality({"camera": {"stray_light": {"fraction": 0.03,
                                                     "kernel_radius_px": 15.0}}})
    stray = simulate(build_scene(spec, twin=twin), request)
    assert next(e for e in stray.plan.effects if e.name == "stray_light").enabled
    assert not next(e for e in clean.plan.effects if e.name == "stray_light").enabled
    wall = clean.image.valid & stray.image.valid & (clean.image.range_m > 1.4)
    assert wall.sum() > 50
    pulled = clean.image.range_m[wall] - stray.image.range_m[wall]
    assert np.median(pulled) > 0.02  # tens of mm nearer: towards the panel at ~0.8 m


@settings(max_examples=60, deadline=None)
@given(fraction=st.floats(0.0, 0.95), radius=radii, low=st.floats(1e-3, 1.0),
       shape=st.tuples(st.integers(1, 12), st.integers(1, 12)), seed=st.integers(0, 2**16))
def test_removing_the_stray_light_gives_back_the_image_it_was_added_to(fraction, radius, low,
                                                                       shape, seed):
    rng = np.random.default_rng(seed)
    z = rng.exponential(size=(2, *shape)) * np.exp(1j * rng.uniform(0, 6.3, size=(2, *shape)))
    weight = np.linspace(low, 1.0, z[0].size).reshape(shape)
    s = StrayLight(fraction, radius)
    back = s.remove(s.apply(z, weight), weight)
    assert np.all(np.isfinite(back))
    # (1 - f) + f a b >= 1 - f: rounding grows at most like 1 / (1 - f)
    np.testing.assert_allclose(back, z, atol=1e-9 / (1.0 - fraction))


def test_removing_refuses_what_cannot_be_undone():
    img = np.ones((6, 8))
    assert StrayLight(0.0, 40.0).remove(img) is img
    assert StrayLight(0.3, 0.0).remove(img) is img
    # every pixel's light spread away, none of its own left: not invertible
    with pytest.raises(ValueError, match=r"fraction = 1 .*\[0, 1\)"):
        StrayLight(1.0, 3.0).remove(img)
    with pytest.raises(ValueError, match="to_irradiance"):
        StrayLight(0.1, 3.0).remove(img, np.zeros((6, 8)))


@settings(max_examples=40, deadline=None)
@given(image=images, fraction=st.floats(0.0, 1.0), radius=radii,
       low=st.floats(1e-3, 1.0))
def test_stray_light_keeps_the_irradiance_when_spread_as_irradiance(image, fraction, radius,
                                                                    low):
    h, w = image.shape
    weight = np.linspace(low, 1.0, h * w).reshape(h, w)  # cos^4 of the field angle, say
    out = StrayLight(fraction, radius).apply(image, weight)
    assert np.all(np.isfinite(out)) and np.all(out >= -1e-9 * max(1.0, image.max()))
    assert (out * weight).sum() == pytest.approx((image * weight).sum(), rel=1e-9, abs=1e-9)
    with pytest.raises(ValueError, match="to_irradiance"):
        StrayLight(max(fraction, 0.1), radius).apply(image, np.zeros((h, w)))


def test_the_planner_turns_stray_light_on_only_when_the_twin_has_it():
    from sim_core.plan import plan_effects

    spec = parse_scene_spec({
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]},
                   "width_px": 32, "height_px": 24, "fx_px": 30.0, "fy_px": 30.0},
        "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [5.0, 5.0]},
                     "material": {"kind": "lambertian", "params": {"albedo": 0.5}},
                     "pose": {"position_m": [0.0, 1.0, 0.0], "rotation_deg": [90, 0, 0]}}]})
    settings = RenderSettings(integrator="direct", spp=1, seed=0)

    def stray(twin, mode="auto"):
        plan = plan_effects(build_scene(spec, twin=twin), settings, mode)
        return next(e for e in plan.effects if e.name == "stray_light")

    assert not stray(None).enabled and "no camera.stray_light" in stray(None).reason
    off = parse_reality({"camera": {"stray_light": {"fraction": 0.0, "kernel_radius_px": 30}}})
    assert not stray(off).enabled and "no light leaves" in stray(off).reason
    assert stray(off, "all").enabled  # --effects all: everything the twin has
    on = parse_reality({"camera": {"stray_light": {"fraction": 0.02, "kernel_radius_px": 30}}})
    assert stray(on).enabled and stray(on).numbers == {"fraction": 0.02, "radius_px": 30.0}
