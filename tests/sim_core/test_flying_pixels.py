"""Flying (mixed) pixels: the rule on synthetic range images (hypothesis) and on rendered frames
(a silhouette in a measured frame has them along its outline, a flat wall has none)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sim_core import frame_io
from sim_core.errors import InvalidInputError
from sim_core.flying_pixels import (
    DEFAULT_RULE,
    FlyingPixelRule,
    flying_pixels,
    second_difference_noise_m,
)
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import lambert, scene_from

H, W = 20, 24
ROYALE_ONLY = FlyingPixelRule(noise_factor=0.0)


def step_edge(near_m: float, far_m: float, mixed_m: float | None, column: int = 11) -> np.ndarray:
    """Columns < ``column`` at ``near_m``, > ``column`` at ``far_m``, ``column`` itself at
    ``mixed_m`` (or ``far_m``)."""
    r = np.full((H, W), far_m)
    r[:, :column] = near_m
    if mixed_m is not None:
        r[:, column] = mixed_m
    return r


def everywhere(shape=(H, W)) -> np.ndarray:
    return np.ones(shape, dtype=bool)


# -- the rule on synthetic images -------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(near=st.floats(0.3, 3.0), gap=st.floats(0.6, 3.0), alpha=st.floats(0.25, 0.75))
def test_a_pixel_between_foreground_and_background_is_flying_and_its_neighbours_are_not(
    near, gap, alpha
):
    far = near + gap
    r = step_edge(near, far, near + alpha * gap)
    for rule in (DEFAULT_RULE, ROYALE_ONLY):
        fp = flying_pixels(r, everywhere(), rule)
        assert fp[:, 11].all()
        assert fp.sum() == H  # the pixels on either side of the edge have a neighbour like them


@settings(max_examples=60, deadline=None)
@given(near=st.floats(0.3, 3.0), gap=st.floats(0.3, 3.0))
def test_a_clean_edge_has_no_flying_pixel(near, gap):
    assert not flying_pixels(step_edge(near, near + gap, None), everywhere()).any()


@settings(max_examples=60, deadline=None)
@given(offset=st.floats(0.2, 5.0), gx=st.floats(-0.2, 0.2), gy=st.floats(-0.2, 0.2))
def test_a_plane_is_never_flying_however_steep(offset, gx, gy):
    """A tilted plane, up to 0.2 m a pixel (a floor at a grazing angle), is a smooth surface:
    each side's slope is extrapolated, so no pixel stands off it."""
    yy, xx = np.mgrid[0:H, 0:W]
    r = offset + 10.0 * abs(gx) + 10.0 * abs(gy) + gx * xx + gy * yy
    assert not flying_pixels(r, everywhere(), ROYALE_ONLY).any()
    assert not flying_pixels(r, everywhere()).any()


def test_a_single_outlier_is_not_a_mixed_pixel():
    """A pixel farther than both its neighbours (e.g. a wrong unwrapping) is not between them."""
    r = np.full((H, W), 1.0)
    r[8, 8] = 3.0
    assert not flying_pixels(r, everywhere(), ROYALE_ONLY).any()


def test_the_threshold_is_royales_ramp_and_grows_with_range():
    rule = FlyingPixelRule()
    t = rule.threshold_m(np.array([0.3, 1.0, 1.0 + 3.5 / 2.0, 4.5, 7.0]))
    np.testing.assert_allclose(t, [0.018, 0.018, 0.079, 0.14, 0.14])
    # a 50 mm step mid-way is flying at 1 m (threshold 18 mm), not at 4.5 m (140 mm)
    near = step_edge(1.0, 1.1, 1.05)
    assert flying_pixels(near, everywhere(), ROYALE_ONLY)[:, 11].all()
    far = step_edge(4.5, 4.6, 4.55)
    assert not flying_pixels(far, everywhere(), ROYALE_ONLY).any()


@settings(max_examples=40, deadline=None)
@given(
    r=arrays(np.float64, (9, 11), elements=st.one_of(
        st.floats(0.1, 8.0), st.just(np.nan), st.just(np.inf), st.just(-np.inf))),
    valid=arrays(np.bool_, (9, 11)),
)
def test_invalid_nan_and_inf_pixels_are_never_flying_and_raise_nothing(r, valid):
    with np.errstate(all="raise"):  # no warning either
        fp = flying_pixels(r, valid)
    assert fp.shape == r.shape and fp.dtype == np.bool_
    assert not fp[~valid].any()
    assert not fp[~np.isfinite(r)].any()


def test_an_invalid_neighbour_gives_no_evidence():
    r = step_edge(1.0, 2.0, 1.5)
    valid = everywhere()
    valid[:, 12] = False  # the background side of the mixed column is invalid
    fp = flying_pixels(r, valid, ROYALE_ONLY)
    assert not fp.any()
    r2 = step_edge(1.0, 2.0, 1.5)
    r2[:, 13] = np.nan  # the outer neighbour is missing
    assert not flying_pixels(r2, everywhere(), ROYALE_ONLY)[:, 11].any()


@pytest.mark.parametrize("column", [0, 1, W - 2, W - 1])
def test_the_image_border_is_safe(column):
    """A mixed column at or next to the border lacks a neighbour or its outer neighbour along
    every direction that crosses the edge: never flying; nothing raised."""
    r = np.full((H, W), 2.0)
    r[:, :column] = 1.0
    r[:, column] = 1.5
    assert not flying_pixels(r, everywhere(), ROYALE_ONLY).any()
    tiny = np.array([[1.0, 1.5, 2.0]])
    assert not flying_pixels(tiny, np.ones((1, 3), bool)).any()


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_rule_is_the_same_in_every_orientation(seed):
    """Transposed or mirrored images have transposed or mirrored flying pixels (the four
    directions map onto each other)."""
    gen = np.random.default_rng(seed)
    r = np.round(gen.choice([1.0, 1.5, 2.0], size=(H, W)) + gen.normal(0, 0.002, (H, W)), 4)
    valid = gen.random((H, W)) > 0.1
    fp = flying_pixels(r, valid, ROYALE_ONLY)
    np.testing.assert_array_equal(flying_pixels(r.T, valid.T, ROYALE_ONLY), fp.T)
    np.testing.assert_array_equal(flying_pixels(r[:, ::-1], valid[:, ::-1], ROYALE_ONLY),
                                  fp[:, ::-1])
    np.testing.assert_array_equal(flying_pixels(r[::-1], valid[::-1], ROYALE_ONLY), fp[::-1])


@pytest.mark.parametrize("sigma_m", [0.001, 0.02, 0.1])
def test_the_local_noise_is_the_second_differences_standard_deviation(sigma_m):
    gen = np.random.default_rng(3)
    r = 1.5 + gen.normal(0.0, sigma_m, (171, 224))
    noise = second_difference_noise_m(r, everywhere(r.shape))
    assert np.median(noise) == pytest.approx(np.sqrt(6.0) * sigma_m, rel=0.08)


@pytest.mark.parametrize("sigma_m", [0.005, 0.05, 0.2])
def test_noise_alone_makes_no_flying_pixel(sigma_m):
    gen = np.random.default_rng(4)
    r = 2.0 + gen.normal(0.0, sigma_m, (171, 224))
    assert flying_pixels(r, everywhere(r.shape)).sum() <= 2  # of 38,304
    # royale's threshold alone flags noise once it is comparable with 18 mm
    if sigma_m >= 0.05:
        assert flying_pixels(r, everywhere(r.shape), ROYALE_ONLY).mean() > 0.1


def test_a_mixed_pixel_well_above_the_noise_is_still_found():
    gen = np.random.default_rng(5)
    r = step_edge(1.0, 2.0, 1.5) + gen.normal(0.0, 0.02, (H, W))
    fp = flying_pixels(r, everywhere())
    assert fp[:, 11].all() and fp.sum() == H


def test_bad_input_names_the_field():
    with pytest.raises(InvalidInputError, match="range_m"):
        flying_pixels(np.ones(5), np.ones(5, bool))
    with pytest.raises(InvalidInputError, match="valid"):
        flying_pixels(np.ones((3, 3)), np.ones((3, 4), bool))
    with pytest.raises(InvalidInputError, match="valid"):
        flying_pixels(np.ones((3, 3)), np.ones((3, 3)))
    with pytest.raises(InvalidInputError, match="far_range_m"):
        FlyingPixelRule(near_range_m=2.0, far_range_m=1.0)
    with pytest.raises(InvalidInputError, match="noise_factor"):
        FlyingPixelRule(noise_factor=-1.0)
    with pytest.raises(InvalidInputError, match="near_threshold_m"):
        FlyingPixelRule(near_threshold_m=float("nan"))


# -- rendered frames --------------------------------------------------------------------------

#: a 64 x 48 camera (focal length 208.33 px) looking along +y; a square plate 0.9 m away whose
#: edges fall on pixel centres (half-width 13.5 px), in front of a wall 1.6 m away
PLATE_HALF_PX = 13.5
PLATE_SIZE_M = 2.0 * 0.9 * PLATE_HALF_PX / 208.33


def _wall(name: str, size_m: float, distance_m: float) -> dict:
    return {"name": name, "mesh": {"kind": "rectangle", "size_m": [size_m, size_m]},
            "material": lambert(0.8),
            "pose": {"position_m": [0.0, distance_m, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}


def _measured(objects: list[dict], tmp_path) -> tuple[np.ndarray, np.ndarray]:
    """Render with the sensor, write the raw frame as a measured frame folder and read it back:
    the reconstruction a measured frame gets."""
    scene = scene_from([0, 0, 0], [0, 1, 0], objects, power_w=8.0, width=64, height=48)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=4, seed=1)))
    image, _ = frame_io.write_measured(tmp_path, frame.raw, scene.camera, {})
    return image.range_m, image.valid


def test_a_silhouette_in_a_measured_frame_is_outlined_by_flying_pixels(tmp_path):
    rng, valid = _measured([_wall("wall", 20.0, 1.6), _wall("plate", PLATE_SIZE_M, 0.9)],
                           tmp_path)
    outline = np.zeros(rng.shape, dtype=bool)
    top, bottom = 24 - int(PLATE_HALF_PX) - 1, 24 + int(PLATE_HALF_PX)  # rows 10 and 37
    left, right = 32 - int(PLATE_HALF_PX) - 1, 32 + int(PLATE_HALF_PX)  # columns 18 and 45
    outline[top:bottom + 1, [left, right]] = True
    outline[[top, bottom], left:right + 1] = True
    fp = flying_pixels(rng, valid)
    assert valid.all()
    assert not (fp & ~outline).any()  # nothing away from the silhouette
    assert (fp & outline).sum() >= 0.8 * outline.sum()  # most of it (measured: 98 of 108)


def test_a_flat_wall_in_a_measured_frame_has_no_flying_pixel(tmp_path):
    rng, valid = _measured([_wall("wall", 20.0, 1.2)], tmp_path)
    assert valid.all()
    assert not flying_pixels(rng, valid).any()
