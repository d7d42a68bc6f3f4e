"""The renderer against closed-form answers."""

import numpy as np
import pytest

from sim_core.camera import pixel_centre_grid
from sim_core.geometry import icosphere_max_chord_error_m
from sim_core.optics import pixel_irradiance_w_m2
from sim_core.pipeline import simulate, z_over_range
from sim_core.render import RenderSettings, render
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from tests.sim_core.scenes import fronto_parallel_wall, lambert, scene_from

CENTRE = RenderSettings(integrator="direct", spp=1, jitter=False)


def test_lambertian_wall_radiance_falls_off_as_cos_cubed():
    # Point source I = P / 4 pi at the camera, wall at z: E = I cos(a) / (z / cos a)^2, and a
    # Lambertian wall sends L = rho / pi * E towards the camera.
    scene = fronto_parallel_wall(distance_m=2.0, albedo=0.8, power_w=1.0)
    lf = render(scene, CENTRE).light_field
    cos_a = z_over_range(scene)
    expected = 0.8 / np.pi * (1.0 / (4 * np.pi)) * cos_a**3 / 2.0**2
    np.testing.assert_allclose(lf.dc_active, expected, rtol=1e-5)
    np.testing.assert_allclose(np.abs(lf.phasor[0]), expected, rtol=1e-5)
    assert np.all(lf.dc_ambient == 0.0)


def test_pixel_irradiance_adds_the_cos4_law_of_seed_eq_32():
    scene = fronto_parallel_wall(distance_m=2.0, albedo=0.8, power_w=1.0)
    lf = render(scene, CENTRE).light_field
    e = pixel_irradiance_w_m2(lf.dc_active, scene.camera, transmittance=0.9, f_number=1.0)
    cos_a = z_over_range(scene)
    expected = (0.9 * np.pi / 4.0 * 0.8 / np.pi / (4 * np.pi) / 4.0) * cos_a**7
    np.testing.assert_allclose(e, expected, rtol=1e-5)


def test_wall_range_is_exact_to_a_tenth_of_a_millimetre():
    scene = fronto_parallel_wall(distance_m=2.0)
    frame = simulate(scene, RenderRequest(CENTRE, ideal=True))
    truth = 2.0 / z_over_range(scene)  # radial distance to the plane y = 2
    err = np.abs(frame.image.range_m - truth)
    assert frame.image.valid.all()
    assert err.max() < 1e-4
    np.testing.assert_allclose(frame.image.depth_z_m, 2.0, atol=1e-4)


def test_sphere_range_matches_the_analytic_ray_sphere_distance():
    radius, centre = 0.5, np.array([0.0, 2.0, 0.0])
    sphere = {"name": "ball", "mesh": {"kind": "sphere", "radius_m": radius, "subdivisions": 6},
              "material": lambert(0.7), "pose": {"position_m": centre.tolist()}}
    scene = scene_from([0.0, 0.0, 0.0], centre, [sphere])
    frame = simulate(scene, RenderRequest(CENTRE, ideal=True))
    d = scene.camera.pixel_directions_world(*_pixel_grid(scene))
    # |t d - c|^2 = r^2 with the camera at the origin: t = d.c - sqrt((d.c)^2 - |c|^2 + r^2)
    dc = d @ centre
    disc = dc**2 - centre @ centre + radius**2
    hits = disc > 0.0
    t = np.where(hits, dc - np.sqrt(np.where(hits, disc, 0.0)), np.nan)
    t = t.reshape(scene.camera.intrinsics.shape)
    # Compare away from the silhouette, where the facets' chord error is the only difference.
    inner = (disc > 0.05 * radius**2).reshape(t.shape)
    # A facet lies at most `chord` inside the sphere along the normal, so along a ray meeting
    # the sphere at incidence theta the range may be longer by up to chord / cos(theta).
    chord = icosphere_max_chord_error_m(radius, 6)
    cos_inc = (np.sqrt(np.maximum(disc, 0.0)) / radius).reshape(t.shape)
    err = frame.image.range_m[inner] - t[inner]
    assert inner.sum() > 1000
    assert np.all(err > -1e-6)
    assert np.all(err < chord / cos_inc[inner] + 1e-6)
    assert not frame.image.valid[~hits.reshape(t.shape)].any()


def _pixel_grid(scene):
    return pixel_centre_grid(scene.camera.intrinsics)


def test_direct_and_one_bounce_path_agree_exactly():
    scene = fronto_parallel_wall()
    a = render(scene, RenderSettings(integrator="direct", spp=4, seed=3)).light_field
    b = render(scene, RenderSettings(integrator="path", max_bounces=1, spp=4, seed=3)).light_field
    np.testing.assert_array_equal(a.phasor, b.phasor)


def test_a_single_plane_has_no_multipath():
    scene = fronto_parallel_wall()
    a = render(scene, RenderSettings(integrator="direct", spp=2, seed=1)).light_field
    b = render(scene, RenderSettings(integrator="path", max_bounces=3, spp=2, seed=1)).light_field
    np.testing.assert_allclose(b.dc_active, a.dc_active, rtol=1e-12)


def test_occluder_casts_a_shadow_from_the_camera_light():
    wall = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [20.0, 20.0]},
            "material": lambert(0.8),
            "pose": {"position_m": [0.0, 2.0, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    # A light 0.3 m to the side of the camera; a small plate in front of the wall shadows it.
    plate = {"name": "plate", "mesh": {"kind": "rectangle", "size_m": [0.2, 0.2]},
             "material": lambert(0.8),
             "pose": {"position_m": [0.0, 1.0, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    scene = build_scene(parse_scene_spec({
        "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]}},
        "illumination": {"power_w": 1.0, "offset_m": [0.3, 0.0, 0.0]},
        "objects": [wall, plate]}))
    lf = render(scene, CENTRE).light_field
    wall_px = lf.object_id == 0
    dark = wall_px & (lf.dc_active == 0.0)
    # The shadow lies on the wall, on the side away from the light (camera -x: image left).
    assert dark.sum() > 50
    cols = np.nonzero(dark)[1]
    assert cols.mean() < 111.5


@pytest.mark.parametrize("power_w", [0.0, 0.5])
def test_radiance_is_linear_in_source_power(power_w):
    scene = fronto_parallel_wall(power_w=power_w)
    ref = fronto_parallel_wall(power_w=1.0)
    a = render(scene, CENTRE).light_field.dc_active
    b = render(ref, CENTRE).light_field.dc_active
    np.testing.assert_allclose(a, power_w * b, rtol=1e-12)
