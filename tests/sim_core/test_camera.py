import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.camera import (
    CAMERA_PRESETS,
    Intrinsics,
    distort_normalized,
    look_at,
    pixel_centre_grid,
    pixel_to_camera_direction,
    undistort_normalized,
)
from sim_core.errors import InvalidInputError
from sim_core.render.kernels import Pinhole, camera_rays


def pico_flexx() -> Intrinsics:
    p = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
    return Intrinsics(p["width_px"], p["height_px"], p["fx_px"], p["fy_px"], p["cx_px"], p["cy_px"])


def test_preset_has_the_seed_table_2_geometry():
    intr = pico_flexx()
    assert intr.shape == (171, 224)
    assert (intr.cx_px, intr.cy_px) == (111.5, 85.0)
    h_fov, v_fov = intr.field_of_view_deg()
    assert 55.0 < h_fov < 63.0 and 43.0 < v_fov < 46.0


def test_principal_point_ray_is_the_optical_axis():
    d = pixel_to_camera_direction(pico_flexx(), np.array([111.5]), np.array([85.0]))
    np.testing.assert_allclose(d, [[0.0, 0.0, 1.0]], atol=1e-15)


def test_pixel_rays_follow_opencv_axes():
    intr = pico_flexx()
    d = pixel_to_camera_direction(intr, np.array([0.0, 223.0, 111.5]), np.array([85.0, 85.0, 0.0]))
    assert d[0, 0] < 0 and d[1, 0] > 0  # column 0 looks left (-x), last column right (+x)
    assert d[2, 1] < 0  # row 0 looks up (-y)


@settings(max_examples=60, deadline=None)
@given(
    k1=st.floats(-0.3, 0.3), k2=st.floats(-0.1, 0.1), p1=st.floats(-0.01, 0.01),
    p2=st.floats(-0.01, 0.01), x=st.floats(-0.5, 0.5), y=st.floats(-0.4, 0.4),
)
def test_undistort_inverts_distort(k1, k2, p1, p2, x, y):
    k = (k1, k2, p1, p2, 0.0)
    xd, yd = distort_normalized(np.array([x]), np.array([y]), k)
    xu, yu = undistort_normalized(xd, yd, k)
    np.testing.assert_allclose([xu[0], yu[0]], [x, y], atol=1e-6)


def test_compiled_ray_kernel_matches_the_reference_with_distortion():
    intr = Intrinsics(224, 171, 208.33, 208.33, 111.5, 85.0, (-0.2, 0.05, 0.001, -0.002, 0.01))
    u, v = pixel_centre_grid(intr)
    r = look_at([1.0, 2.0, 3.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])[:3, :3]
    ref = pixel_to_camera_direction(intr, u, v) @ r.T
    got = camera_rays(u, v, Pinhole.of(intr, r))
    np.testing.assert_allclose(got, ref, atol=1e-12)


def test_look_at_points_z_at_the_target_and_y_down():
    m = look_at([1.5, 1.5, 1.5], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    r = m[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r[:, 2], -np.ones(3) / np.sqrt(3.0))
    assert r[2, 1] < 0.0  # image down (camera +y) points down in the world (-z)


def test_zero_length_look_at_names_the_field():
    with pytest.raises(InvalidInputError, match=r"camera\.pose\.look_at_m"):
        look_at([1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.0, 0.0, 1.0])


def test_up_parallel_to_view_is_rejected():
    with pytest.raises(InvalidInputError, match=r"camera\.pose\.up"):
        look_at([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])
