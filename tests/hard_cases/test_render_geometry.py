"""Hard cases of the geometry: grazing views and light, back faces, rays starting on surfaces,
coincident and tiny triangles, scenes far from the origin, surfaces at the light.

Closed forms: a Lambertian surface lit by the camera's isotropic source I has the radiance
L = rho / pi * I * cos(theta_l) / d^2 (d and theta_l towards the source), and lit by a
collimated ambient source of irradiance E, L = rho / pi * E * cos(theta_s). Every case also
checks stability: the same frame after a tiny perturbation of its input (a pose by 1e-9 m or
1e-9 rad, a parameter by 1e-9 relative) differs by no more than the stated Lipschitz bound plus
the rounding of Embree's float32 geometry.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from sim_core.errors import SceneError
from sim_core.geometry import face_normals, rotation_matrix_xyz_deg
from sim_core.pipeline import simulate
from sim_core.render import render
from sim_core.render.integrator import MIN_LIGHT_DISTANCE_M
from sim_core.render.lightfield import LightField
from sim_core.render_request import RenderRequest
from tests.hard_cases.helpers import (
    CENTRE,
    I_1W,
    PATH,
    assert_frame_bounded,
    assert_stable,
    build,
    camera,
    lambert,
    pixel_rays,
    rectangle,
)

#: relative precision of Embree's float32 hit distances (a few ulps of 2^-24)
F32 = 4.0 * 2.0**-24

_LIGHT_FIELD_ARRAYS = ("dc_active", "dc_ambient", "phasor", "truth_range_m")


def _assert_light_fields_equal(a: LightField, b: LightField, rtol: float) -> None:
    for name in _LIGHT_FIELD_ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        scale = np.nanmax(np.abs(x)) if np.isfinite(x).any() else 0.0
        np.testing.assert_allclose(x, y, rtol=0.0, atol=rtol * scale + 1e-300, err_msg=name)
    np.testing.assert_array_equal(a.hit, b.hit)


# -------------------------------------------------------------------------------------------
# Grazing incidence and exit: a wall seen and lit at 89.99 degrees
# -------------------------------------------------------------------------------------------
GRAZING_DEG = 89.99
WALL_DISTANCE_M = 2.0


def grazing_wall(angle_deg=GRAZING_DEG, camera_shift=(0.0, 0.0, 0.0), look_shift=0.0,
                 albedo=0.8):
    """A wall through (0, 2, 0) whose normal makes ``angle_deg`` with the view axis (+y).

    The 8 x 6 camera has a field of view of 8e-6 rad, so every pixel sees the wall within
    5e-6 rad of ``angle_deg`` (the camera's own source lights it at the same angle).
    """
    s = np.asarray(camera_shift, dtype=float)
    wall = rectangle("wall", (50.0, 50.0), lambert(albedo), (0.0, WALL_DISTANCE_M, 0.0),
                     (90.0, 0.0, angle_deg))
    cam = camera(s, s + np.array([look_shift, 1.0, 0.0]), width=8, height=6, f_px=1e6)
    return build(cam, [wall])


def ray_plane(scene, point_m, normal):
    """Distances along the pixel-centre rays to a plane and |cos| of the incidence, (H, W)."""
    d = pixel_rays(scene)
    t = ((np.asarray(point_m) - scene.camera.position_m) @ normal) / (d @ normal)
    shape = scene.camera.intrinsics.shape
    return t.reshape(shape), np.abs(d @ normal).reshape(shape)


def test_wall_seen_and_lit_at_89_99_degrees_follows_the_cos_law():
    scene = grazing_wall()
    lf = render(scene, CENTRE).light_field
    t, cos_i = ray_plane(scene, (0.0, WALL_DISTANCE_M, 0.0), scene.normals[0])
    assert lf.hit.all()
    assert cos_i.max() < math.cos(math.radians(GRAZING_DEG - 0.001))
    # float32 hit distances: a relative error of ~1e-7 of the vertex coordinates becomes
    # 1e-7 / cos(theta) = 6e-4 of the distance at worst; measured: 7e-7.
    np.testing.assert_allclose(lf.truth_range_m, t, rtol=1e-5)
    expected = 0.8 / np.pi * I_1W * cos_i / t**2
    np.testing.assert_allclose(lf.dc_active, expected, rtol=1e-5)
    np.testing.assert_allclose(np.abs(lf.phasor[0]), expected, rtol=1e-5)


def test_grazing_wall_frame_is_finite_and_bounded_with_every_stage():
    scene = grazing_wall()
    assert_frame_bounded(simulate(scene, RenderRequest(PATH)))
    assert_frame_bounded(simulate(scene, RenderRequest(PATH, effects="all", ideal=True)))


@pytest.mark.parametrize(
    ("perturbed", "range_tol_m", "radiance_rel"),
    [
        # 1e-9 m along the view: the range moves by 1e-9 m.
        (dict(camera_shift=(0.0, 1e-9, 0.0)), 1e-6, 1e-6),
        # 1e-9 m across the wall: the range moves by 1e-9 / cos(89.99 deg) = 5.7e-6 m, the
        # phase of the phasor by 4 pi f / c * 5.7e-6 m = 1.4e-5 rad.
        (dict(camera_shift=(1e-9, 0.0, 0.0)), 2e-5, 5e-5),
        # 1e-9 rad of view direction: 1e-9 * 2 m / cos = 1.1e-5 m, the phase by 3e-5 rad.
        (dict(look_shift=1e-9), 5e-5, 1e-4),
        # albedo 1e-9 relative: the radiance moves by 1e-9 relative, the range not at all.
        (dict(albedo=0.8 * (1.0 + 1e-9)), 1e-12, 1e-8),
        # 1e-9 deg of wall tilt: 1.7e-11 rad / cos(theta) = 1e-7 relative; the range 2.4e-6 m
        # (one float32 step).
        (dict(angle_deg=GRAZING_DEG + 1e-9), 1e-5, 3e-5),
    ],
    ids=["along-view", "across-wall", "view-direction", "albedo", "wall-tilt"],
)
def test_grazing_wall_is_stable_under_tiny_perturbations(perturbed, range_tol_m, radiance_rel):
    # Bounds: the exact change (the Lipschitz constant is 1 / cos(89.99 deg) = 5730 for moves
    # across the wall) plus float32 rounding of the geometry (F32 * 2 m / cos = 1.1e-3 m in the
    # worst case; measured 0). The ideal sensor makes the range a deterministic function.
    base = simulate(grazing_wall(), RenderRequest(CENTRE, ideal=True))
    moved = simulate(grazing_wall(**perturbed), RenderRequest(CENTRE, ideal=True))
    assert_stable(base, moved, range_tol_m=range_tol_m, radiance_rel=radiance_rel)


# -------------------------------------------------------------------------------------------
# Back faces and winding
# -------------------------------------------------------------------------------------------
def cluttered_scene(offset=(0.0, 0.0, 0.0), power_w=5.0):
    """A wall, a tiled floor, a film-covered box and a regolith ball: every material model."""
    o = np.asarray(offset, dtype=float)
    objs = [
        rectangle("wall", (6.0, 6.0), lambert(0.7), o + np.array([0.0, 3.0, 0.0]),
                  (90.0, 0.0, 0.0)),
        rectangle("floor", (6.0, 6.0), {"preset": "white-matte-tile"},
                  o + np.array([0.0, 1.5, -0.8])),
        {"name": "box", "mesh": {"kind": "box", "size_m": [0.4, 0.4, 0.4]},
         "material": {"preset": "thermal-control-film"},
         "pose": {"position_m": (o + np.array([0.3, 2.0, -0.2])).tolist(),
                  "rotation_deg": [10, 20, 30]}},
        {"name": "ball", "mesh": {"kind": "sphere", "radius_m": 0.3, "subdivisions": 2},
         "material": {"preset": "vesta-regolith"},
         "pose": {"position_m": (o + np.array([-0.5, 2.2, 0.1])).tolist()}},
    ]
    return build(camera(o, o + np.array([0.0, 1.0, 0.0])), objs, power_w=power_w)


def inverted_winding(scene):
    """The same scene with every triangle's corner order reversed (normals flipped)."""
    tris = np.ascontiguousarray(scene.triangles_m[:, ::-1])
    return dataclasses.replace(scene, triangles_m=tris, normals=face_normals(tris))


@pytest.mark.parametrize("settings", [CENTRE, PATH], ids=["direct", "path"])
def test_inverted_winding_renders_the_same_image(settings):
    # Shading is two-sided: the renderer turns every normal towards the incoming ray, so the
    # winding must not matter (only Embree's float32 hit distance may differ by an ulp).
    scene = cluttered_scene()
    flipped = inverted_winding(scene)
    np.testing.assert_allclose(flipped.normals, -scene.normals, atol=1e-12)
    a, b = render(scene, settings).light_field, render(flipped, settings).light_field
    _assert_light_fields_equal(a, b, rtol=1e-6)


def test_wall_seen_from_its_back_is_lit_like_its_front():
    def wall(rotation_x_deg):
        objs = [rectangle("wall", (20.0, 20.0), lambert(0.8), (0.0, 2.0, 0.0),
                          (rotation_x_deg, 0.0, 0.0))]
        return build(camera((0, 0, 0), (0, 1, 0)), objs)

    front, back = wall(90.0), wall(-90.0)
    assert front.normals[0] @ [0, 1, 0] < 0.0 < back.normals[0] @ [0, 1, 0]
    for settings in (CENTRE, PATH):
        a, b = render(front, settings).light_field, render(back, settings).light_field
        _assert_light_fields_equal(a, b, rtol=1e-6)
        np.testing.assert_allclose(b.truth_normal.reshape(-1, 3) @ [0, 1, 0], -1.0)


# -------------------------------------------------------------------------------------------
# Rays that start on a surface (self-intersection)
# -------------------------------------------------------------------------------------------
def sunlit_plane(elevation_deg, offset=(0.0, 0.0, 0.0), rotation_deg=(3.0, -7.0, 21.0)):
    """A tilted Lambertian plane lit by the Sun ``elevation_deg`` above the plane."""
    o = np.asarray(offset, dtype=float)
    r = rotation_matrix_xyz_deg(rotation_deg)
    n = r @ [0.0, 0.0, 1.0]
    e, az = math.radians(elevation_deg), math.radians(30.0)
    sun = -math.sin(e) * n + math.cos(e) * (r @ [math.cos(az), math.sin(az), 0.0])
    plane = rectangle("plane", (40.0, 40.0), lambert(0.6), o, rotation_deg)
    cam = camera(o + r @ [0.0, -3.0, 1.5], o + r @ [0.0, 2.0, 0.0], up=n)
    scene = build(cam, [plane], ambient={"sun": {"direction": sun.tolist()}})
    return scene, abs(float(sun @ n))


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e6, -2e6, 5e5)], ids=["origin", "far"])
@pytest.mark.parametrize("elevation_deg", [0.01, 0.1, 1.0, 30.0])
def test_plane_lit_at_grazing_sun_has_no_self_shadow_speckle(elevation_deg, offset):
    # Every shadow ray starts on the plane and leaves it at `elevation_deg`: a shadow ray that
    # re-hit its own plane would zero its pixel (speckle). The cos law is exact per pixel.
    scene, cos_s = sunlit_plane(elevation_deg, offset)
    lf = render(scene, CENTRE).light_field
    expected = 0.6 / np.pi * scene.ambient[0].irradiance_w_m2 * cos_s
    assert lf.hit.mean() > 0.7
    # 1e-8: the far plane's hit points carry float32 rounding into nothing but the footprint
    # test of the light; the radiance itself is the same for every point of the plane.
    np.testing.assert_allclose(lf.dc_ambient[lf.hit], expected, rtol=1e-8)
    assert np.all(lf.dc_ambient[~lf.hit] == 0.0)


@pytest.mark.parametrize("elevation_deg", [0.01, 1.0])
def test_grazing_sunlight_is_stable_under_a_nanoradian_turn_of_the_sun(elevation_deg):
    # cos_s = sin(elevation): a turn by 1e-9 rad moves it by 1e-9 / tan(elevation) relative
    # (5.7e-6 at 0.01 deg); nothing else changes.
    scene, cos_s = sunlit_plane(elevation_deg)
    turned, cos_t = sunlit_plane(elevation_deg + math.degrees(1e-9))
    a = simulate(scene, RenderRequest(CENTRE, effects="all", ideal=True))
    b = simulate(turned, RenderRequest(CENTRE, effects="all", ideal=True))
    rel = 1e-9 / math.tan(math.radians(elevation_deg))
    assert abs(cos_t / cos_s - 1.0) == pytest.approx(rel, rel=1e-3)
    assert_stable(a, b, range_tol_m=1e-12, radiance_rel=2.0 * rel)


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e6, 1e6, 0.0)], ids=["origin", "far"])
@pytest.mark.parametrize("light_height_m", [0.02, 0.002, 1e-4])
def test_floor_lit_by_a_grazing_camera_source_follows_the_cos_law(light_height_m, offset):
    # The camera looks down at a floor from 2 m; its source sits 30 m to the side, only
    # `light_height_m` above the floor (incidence up to 89.9998 deg at the floor).
    o = np.asarray(offset, dtype=float)
    floor = rectangle("floor", (4.0, 4.0), lambert(0.5), o)
    cam = camera(o + np.array([0.0, 0.0, 2.0]), o, up=(0.0, 1.0, 0.0))
    probe = build(cam, [floor])
    light_world = np.array([-30.0, 0.0, light_height_m - 2.0])  # relative to the camera
    offset_cam = probe.camera.rotation.T @ light_world
    scene = build(cam, [floor], light={"offset_m": offset_cam.tolist()})
    lf = render(scene, CENTRE).light_field
    d = pixel_rays(scene)
    t = 2.0 / -d[:, 2]
    p = scene.camera.position_m + t[:, None] * d
    to_light = scene.light.position_m - p
    dist = np.linalg.norm(to_light, axis=1)
    cos_l = (to_light[:, 2] / dist).reshape(lf.shape)
    expected = 0.5 / np.pi * I_1W * cos_l / dist.reshape(lf.shape) ** 2
    # No pixel may be shadowed by its own floor (speckle) ...
    assert lf.hit.all() and np.all(lf.dc_active > 0.0)
    # ... and the cos law holds up to float32 hit points: a height error of F32 * 2 m moves
    # cos by 1e-7 m / 30 m, i.e. |ratio - 1| <= 1e-5 + 1e-8 / cos.
    err = np.abs(lf.dc_active / expected - 1.0)
    assert np.all(err <= 1e-5 + 1e-8 / cos_l)


CONVEX = [
    ({"kind": "sphere", "radius_m": 0.5, "subdivisions": 3}, lambert(0.9)),
    ({"kind": "box", "size_m": [0.6, 0.8, 0.4]}, {"preset": "thermal-control-film"}),
    ({"kind": "sphere", "radius_m": 0.5, "subdivisions": 2},
     {"kind": "seed-microfacet",
      "params": {"ks": 1.0, "kd": 0.0, "sigma": 1.0, "f0": 1.0, "fresnel_exponent": 0.0}}),
]


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e6, -1e6, 3e5)], ids=["origin", "far"])
@pytest.mark.parametrize(("mesh", "material"), CONVEX, ids=["ball", "box", "rough-ball"])
def test_convex_object_has_no_multipath_so_paths_equal_direct_light(mesh, material, offset):
    # Every secondary ray starts on a convex surface and can never meet it again: if one did
    # (self-intersection), the path-traced image would gain light over the direct one. NEE
    # shadow rays from a convex surface facing the source are never blocked either.
    o = np.asarray(offset, dtype=float)
    obj = {"name": "object", "mesh": mesh, "material": material,
           "pose": {"position_m": (o + np.array([0.0, 2.0, 0.0])).tolist(),
                    "rotation_deg": [17, 33, 5]}}
    scene = build(camera(o, o + np.array([0.0, 1.0, 0.0])), [obj],
                  ambient={"sun": {"direction": [0.3, 0.2, -0.93]}})
    deep = dataclasses.replace(PATH, max_bounces=4)
    a = render(scene, dataclasses.replace(deep, integrator="direct")).light_field
    b = render(scene, deep).light_field
    assert a.hit.sum() > 50
    np.testing.assert_array_equal(a.dc_active, b.dc_active)
    np.testing.assert_array_equal(a.dc_ambient, b.dc_ambient)
    np.testing.assert_array_equal(a.phasor, b.phasor)


def test_sunlit_facets_of_a_ball_are_never_shadowed_by_the_ball():
    ball = {"name": "ball", "mesh": {"kind": "sphere", "radius_m": 0.5, "subdivisions": 3},
            "material": lambert(0.9), "pose": {"position_m": [0.0, 2.0, 0.0]}}
    sun = np.array([0.6, 0.3, -0.74])
    sun /= np.linalg.norm(sun)
    scene = build(camera((0, 0, 0), (0, 1, 0)), [ball],
                  ambient={"sun": {"direction": sun.tolist()}})
    lf = render(scene, CENTRE).light_field
    cos_s = np.maximum(lf.truth_normal @ -sun, 0.0)
    expected = 0.9 / np.pi * scene.ambient[0].irradiance_w_m2 * cos_s
    np.testing.assert_allclose(lf.dc_ambient[lf.hit], expected[lf.hit], rtol=1e-9, atol=1e-300)
    assert (cos_s[lf.hit] > 0.0).sum() > 50 and (cos_s[lf.hit] == 0.0).sum() > 50


# -------------------------------------------------------------------------------------------
# Coincident faces
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "second_rotation_deg",
    [(90.0, 0.0, 0.0), (-90.0, 0.0, 0.0), (90.0, 37.0, 0.0), (-90.0, 11.0, 0.0)],
    ids=["same-triangles", "flipped", "rotated-in-plane", "flipped-and-rotated"],
)
def test_coincident_rectangles_show_one_material_or_the_other_per_pixel(second_rotation_deg):
    objs = [rectangle("dark", (10.0, 10.0), lambert(0.2), (0.0, 2.0, 0.0), (90.0, 0.0, 0.0)),
            rectangle("bright", (10.0, 10.0), lambert(0.8), (0.0, 2.0, 0.0),
                      second_rotation_deg)]
    scene = build(camera((0, 0, 0), (0, 1, 0)), objs)
    lf = render(scene, CENTRE).light_field
    cos_a = pixel_rays(scene)[:, 1].reshape(lf.shape)
    ratio = lf.dc_active / (I_1W / np.pi * cos_a**3 / 2.0**2)
    dark, bright = np.isclose(ratio, 0.2, rtol=1e-5), np.isclose(ratio, 0.8, rtol=1e-5)
    assert np.all(dark | bright)
    np.testing.assert_array_equal(bright, lf.object_id == 1)
    np.testing.assert_array_equal(dark, lf.object_id == 0)
    # Path tracing: finite, and a jittered pixel mixes the two at most.
    frame = simulate(scene, RenderRequest(PATH, effects="all"))
    assert_frame_bounded(frame)
    r = frame.light_field.dc_active / (I_1W / np.pi * cos_a**3 / 2.0**2)
    assert np.all((r > 0.2 * 0.95) & (r < 0.8 * 1.05))


def test_coincident_rectangles_stay_one_or_the_other_after_a_nanometre_shift():
    # Which of two coincident faces a ray meets is arbitrary; after a 1e-9 m shift of one of
    # them (below float32 resolution at 2 m) it must still be one of the two, never a mixture,
    # a hole or a NaN.
    for shift in (1e-9, -1e-9):
        objs = [rectangle("dark", (10.0, 10.0), lambert(0.2), (0.0, 2.0, 0.0), (90.0, 0.0, 0.0)),
                rectangle("bright", (10.0, 10.0), lambert(0.8), (0.0, 2.0 + shift, 0.0),
                          (90.0, 37.0, 0.0))]
        scene = build(camera((0, 0, 0), (0, 1, 0)), objs)
        lf = render(scene, CENTRE).light_field
        cos_a = pixel_rays(scene)[:, 1].reshape(lf.shape)
        ratio = lf.dc_active / (I_1W / np.pi * cos_a**3 / 2.0**2)
        assert lf.hit.all()
        assert np.all(np.isclose(ratio, 0.2, rtol=1e-5) | np.isclose(ratio, 0.8, rtol=1e-5))


# -------------------------------------------------------------------------------------------
# Degenerate and tiny triangles
# -------------------------------------------------------------------------------------------
def obj_file(path: Path, triangles: np.ndarray) -> str:
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for tri in triangles for x, y, z in tri]
    lines += [f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}" for k in range(len(triangles))]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def tiny_triangles(edge_m: float, n: int = 200, distance_m: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(0)
    base = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) * edge_m
    centres = np.stack(
        [rng.uniform(-0.5, 0.5, n), np.full(n, distance_m), rng.uniform(-0.4, 0.4, n)], axis=1
    )
    return base[None] + centres[:, None]


def test_nanometre_triangles_in_front_of_a_wall_render_finite(tmp_path):
    # 1e-9 m triangles are kept (area 5e-19 m^2 > the 1e-24 m^2 floor) but collapse to points
    # in float32 at 1 m: Embree never hits them, and the wall behind shows through.
    tiny = {"name": "dust", "mesh": {"kind": "file",
                                     "path": obj_file(tmp_path / "dust.obj", tiny_triangles(1e-9))},
            "material": lambert(0.9)}
    wall = rectangle("wall", (10.0, 10.0), lambert(0.5), (0.0, 2.0, 0.0), (90.0, 0.0, 0.0))
    scene = build(camera((0, 0, 0), (0, 1, 0)), [wall, tiny], power_w=5.0)
    assert scene.n_triangles == 202
    np.testing.assert_allclose(np.linalg.norm(scene.normals, axis=1), 1.0)
    frame = simulate(scene, RenderRequest(PATH))
    assert_frame_bounded(frame)
    assert frame.image.valid.all()
    alone = simulate(build(camera((0, 0, 0), (0, 1, 0)), [tiny]), RenderRequest(PATH))
    assert_frame_bounded(alone)
    assert not alone.image.valid.any()


@pytest.mark.parametrize("edge_m", [1e-12, 1e-13])
def test_triangles_below_the_area_floor_are_rejected_as_degenerate(tmp_path, edge_m):
    tiny = {"name": "dust", "mesh": {"kind": "file",
                                     "path": obj_file(tmp_path / "d.obj", tiny_triangles(edge_m))},
            "material": lambert(0.9)}
    with pytest.raises(SceneError, match="degenerate"):
        build(camera((0, 0, 0), (0, 1, 0)), [tiny])


@pytest.mark.parametrize("distance_m", [1e-3, 2e-4])
def test_nanometre_triangle_next_to_the_camera_is_hit_and_lit_finitely(tmp_path, distance_m):
    # Near the render origin float32 resolves 1e-9 m: the triangle is hit by every pixel of a
    # camera with a field of view of 1e-7 rad, and lit by the cos law at `distance_m`.
    tri = np.array([[[-1e-9, distance_m, -1e-9], [1e-9, distance_m, -1e-9],
                     [0.0, distance_m, 1e-9]]])
    obj = {"name": "speck", "mesh": {"kind": "file", "path": obj_file(tmp_path / "s.obj", tri)},
           "material": lambert(0.9)}
    scene = build(camera((0, 0, 0), (0, 1, 0), width=9, height=9, f_px=1e8), [obj])
    lf = render(scene, CENTRE).light_field
    assert lf.hit.all()
    np.testing.assert_allclose(lf.truth_range_m, distance_m, rtol=1e-6)
    cos_l = pixel_rays(scene)[:, 1].reshape(lf.shape)
    np.testing.assert_allclose(lf.dc_active, 0.9 / np.pi * I_1W * cos_l / distance_m**2,
                               rtol=1e-5)
    assert_frame_bounded(simulate(scene, RenderRequest(PATH)))


# -------------------------------------------------------------------------------------------
# Surfaces at the light source
# -------------------------------------------------------------------------------------------
def wall_at(distance_m, material):
    wall = rectangle("wall", (1.0, 1.0), material, (0.0, distance_m, 0.0), (90.0, 0.0, 0.0))
    return build(camera((0, 0, 0), (0, 1, 0), width=3, height=3, f_px=1e4), [wall])


CLOSE_MATERIALS = [
    lambert(0.8),
    {"kind": "seed-microfacet", "params": {"ks": 0.5, "kd": 0.3, "sigma": 0.05}},
]


@pytest.mark.parametrize("material", CLOSE_MATERIALS, ids=["lambertian", "seed-microfacet"])
def test_surface_closer_than_the_light_clamp_sees_the_capped_irradiance(material):
    # The clamp caps the irradiance at I / d_min^2; the direction to the light stays a unit
    # vector (the BRDF contract). So the radiance at the normal view is that at d_min.
    at_clamp = render(wall_at(MIN_LIGHT_DISTANCE_M, material), CENTRE).light_field
    for distance_m in (0.5 * MIN_LIGHT_DISTANCE_M, 1e-5):
        inside = render(wall_at(distance_m, material), CENTRE).light_field
        np.testing.assert_allclose(inside.dc_active[1, 1], at_clamp.dc_active[1, 1], rtol=1e-4)


@pytest.mark.parametrize("material", CLOSE_MATERIALS, ids=["lambertian", "seed-microfacet"])
def test_surface_at_the_light_stays_finite_and_lit(material):
    # Holds before and after the fix of the clamp above.
    for distance_m in (MIN_LIGHT_DISTANCE_M, 1e-5, 1e-7):
        lf = render(wall_at(distance_m, material), CENTRE).light_field
        assert np.all(np.isfinite(lf.dc_active)) and np.all(np.isfinite(lf.phasor))
        assert lf.dc_active[1, 1] > 0.0
    assert_frame_bounded(simulate(wall_at(1e-5, material), RenderRequest(PATH)))


# -------------------------------------------------------------------------------------------
# Far from the origin
# -------------------------------------------------------------------------------------------
FAR_OFFSETS = [(1e6, 0.0, 0.0), (1e6, -1e6, 1e6), (-3e6, 2e6, 1e6)]


@pytest.mark.parametrize("offset", FAR_OFFSETS, ids=lambda o: f"{o[0]:g},{o[1]:g},{o[2]:g}")
@pytest.mark.parametrize("settings", [CENTRE, PATH], ids=["direct", "path"])
def test_scene_translated_by_a_million_metres_gives_the_same_range_image(settings, offset):
    # Embree is float32 (6 cm resolution at 1e6 m); the tracer renders relative to the camera.
    near = simulate(cluttered_scene(), RenderRequest(settings, ideal=True))
    far = simulate(cluttered_scene(offset), RenderRequest(settings, ideal=True))
    np.testing.assert_array_equal(near.image.valid, far.image.valid)
    v = near.image.valid
    assert np.max(np.abs(near.image.range_m[v] - far.image.range_m[v])) < 1e-4
    np.testing.assert_allclose(far.light_field.truth_range_m, near.light_field.truth_range_m,
                               atol=1e-4)
    np.testing.assert_allclose(far.light_field.dc_active, near.light_field.dc_active,
                               rtol=1e-5, atol=1e-12 * near.light_field.dc_active.max())
    assert_frame_bounded(far)


def test_far_scene_is_stable_under_a_nanometre_camera_move():
    o = np.array(FAR_OFFSETS[1])
    base = cluttered_scene(o)
    frame = simulate(base, RenderRequest(PATH))
    moved = dataclasses.replace(
        base, camera=dataclasses.replace(base.camera, world_from_camera=_shifted(base, 1e-9)))
    # The same seed draws the same noise; a 1e-9 m move changes hit distances by 1e-9 m plus
    # float32 rounding of the camera-relative geometry (F32 * 3 m = 7e-7 m).
    assert_stable(frame, simulate(moved, RenderRequest(PATH)), range_tol_m=1e-4, radiance_rel=1e-5)


def _shifted(scene, metres):
    m = scene.camera.world_from_camera.copy()
    m[:3, 3] += metres * np.array([1.0, -1.0, 1.0]) / math.sqrt(3.0)
    return m
