"""The effect planner decides from numbers, and its decisions hold."""

import numpy as np
import pytest

from sim_core.pipeline import simulate
from sim_core.plan import plan_effects
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from tests.sim_core.scenes import small_example

PATH = RenderSettings(integrator="path", spp=8, max_bounces=3, seed=4)


def lone_box(**ambient) -> object:
    spec = {
        "camera": {"pose": {"position_m": [0, -1.0, 0.0], "look_at_m": [0, 0, 0],
                            "up": [0, 0, 1]}, "width_px": 64, "height_px": 48,
                   "fx_px": 59.5, "fy_px": 59.5},
        "illumination": {"power_w": 1.0},
        "objects": [{"name": "box", "mesh": {"kind": "box", "size_m": [0.3, 0.3, 0.3]},
                     "material": "thermal-control-film",
                     "pose": {"rotation_deg": [10, 20, 30]}}],
        "ambient": ambient,
    }
    return build_scene(parse_scene_spec(spec))


def effect(plan, name):
    return next(e for e in plan.effects if e.name == name)


def test_convex_object_renders_direct_only_with_the_same_depth_and_fewer_rays():
    scene = lone_box()
    auto = simulate(scene, RenderRequest(PATH, effects="auto", ideal=True))
    full = simulate(scene, RenderRequest(PATH, effects="all", ideal=True))
    mp = effect(auto.plan, "multipath")
    assert not mp.enabled and mp.numbers["range_bias_p95_mm"] == 0.0
    assert effect(full.plan, "multipath").enabled
    both = auto.image.valid & full.image.valid
    assert both.sum() > 200
    # Nothing reflects light back onto a convex object: the extra bounces add nothing.
    np.testing.assert_allclose(auto.image.range_m[both], full.image.range_m[both], atol=1e-9)
    assert auto.rays_traced < full.rays_traced


def test_corner_turns_multipath_on_with_a_bias_in_millimetres():
    plan = plan_effects(small_example("corner", width=64), PATH, ideal=False)
    mp = effect(plan, "multipath")
    assert mp.enabled
    assert mp.numbers["indirect_to_direct"] > 0.2
    assert mp.numbers["range_bias_p95_mm"] > plan.tolerance_mm
    assert "mm" in mp.reason


def test_solar_beam_that_misses_the_target_turns_ambient_and_sbi_off():
    beam = {"solar_simulator": {"direction": [0.0, 1.0, 0.0], "beam_centre_m": [3.0, 0.0, 0.0]}}
    plan = plan_effects(lone_box(**beam), PATH)
    amb = effect(plan, "ambient")
    assert not amb.enabled and "lit" in amb.reason
    assert not effect(plan, "sbi").enabled


def test_solar_beam_on_the_target_turns_ambient_and_sbi_on():
    beam = {"solar_simulator": {"direction": [0.3, 1.0, -0.2], "beam_centre_m": [0, 0, 0]}}
    plan = plan_effects(lone_box(**beam), PATH)
    assert effect(plan, "ambient").enabled
    assert effect(plan, "sbi").enabled
    assert effect(plan, "ambient").numbers["ambient_e_max"] > 1e4


def test_ideal_mode_turns_noise_and_sbi_off_and_every_effect_has_a_reason():
    plan = plan_effects(lone_box(), PATH, ideal=True)
    assert not plan.enabled("noise") and not plan.enabled("sbi")
    names = [e.name for e in plan.effects]
    assert {"multipath", "ambient", "sbi", "noise", "diffraction", "pixel_aperture"} <= set(names)
    assert all(e.reason for e in plan.effects)
    text = plan.explain()
    for n in names:
        assert n in text


def test_user_tolerance_changes_the_multipath_decision():
    scene = small_example("corner", width=48)
    strict = plan_effects(scene, PATH, tolerance_mm=0.01)
    lax = plan_effects(scene, PATH, tolerance_mm=1e4)
    assert effect(strict, "multipath").enabled and not effect(lax, "multipath").enabled


def test_unknown_mode_is_rejected():
    with pytest.raises(ValueError, match="auto"):
        plan_effects(lone_box(), PATH, mode="some")
