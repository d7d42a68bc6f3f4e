"""The MTF chain at the image border: a hot pixel on every edge and corner with each component
alone, motion along and across the border, all-zero images, and images smaller than the
point-spread function. (The whole chain on a full-size image is in tests/sim_core/test_optics.py.)

A linear filter of light may spread a hot pixel and ring a little below zero, but it may not
create light, move it to the far side of the image (wrap-around), or depend on how far away
the other borders are.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim_core import optics

SMALL = (24, 32)  # the hard cases' camera
LARGE = (171, 224)  # the CamBoard pico flexx

#: (component, most negative value, largest value half an image away), both as fractions of
#: the output's peak. The Gaussian and the Airy pattern are positive and compact. The box-like
#: components (pixel aperture, motion) are sincs sampled on the frequency grid: their kernels
#: ring like a box's Gibbs overshoot and have 1/x tails, which reach the far side of a 32 px
#: image at up to 2 % of the peak for a 5 px diagonal motion (measured: 1.8 %); the first-order
#: low-pass has a ripple of under 1 %.
COMPONENTS = [
    (optics.Diffraction(850e-9, 1.8, 17.5e-6), 0.002, 1e-4),
    (optics.PixelAperture(0.6), 0.02, 1e-3),
    (optics.Electronics(0.4), 0.01, 1e-3),
    (optics.LinearMotion(5.0, 30.0), 0.25, 0.03),
    (optics.LinearMotion(6.0, 0.0), 0.1, 0.005),
    (optics.Vibration(1.2), 1e-4, 1e-4),
]
IDS = ["diffraction", "pixel-aperture", "electronics", "motion-30deg", "motion-along-x",
       "vibration"]


def border_pixels(shape):
    h, w = shape
    return [(0, 0), (0, w // 2), (0, w - 1), (h // 2, 0), (h // 2, w - 1), (h - 1, 0),
            (h - 1, w // 2), (h - 1, w - 1)]


def hot(shape, where, value=1.0):
    img = np.zeros(shape)
    img[where] = value
    return img


def far_side(shape, where):
    """Mask of the rows and columns half an image away from ``where`` (where wrap-around
    would put the light)."""
    h, w = shape
    r, c = where
    mask = np.zeros(shape, dtype=bool)
    mask[(r + h // 2) % h, :] = True
    mask[:, (c + w // 2) % w] = True
    return mask


@pytest.mark.parametrize("shape", [SMALL, LARGE], ids=["32x24", "224x171"])
@pytest.mark.parametrize(("component", "ringing", "far"), COMPONENTS, ids=IDS)
def test_hot_pixel_on_the_border_spreads_locally_with_bounded_ringing(
    component, ringing, far, shape
):
    for where in border_pixels(shape):
        out = optics.apply_mtf(hot(shape, where), [component])
        assert np.all(np.isfinite(out))
        peak = out.max()
        assert 0.0 < peak <= 1.0 + 1e-12
        assert out.min() >= -ringing * peak
        # no light on the far side of the image (beyond the kernel's own tails) ...
        assert np.abs(out[far_side(shape, where)]).max() < far * peak
        # ... and none created (the crop may cut off negative lobes: the tails' size)
        assert out.sum() <= 1.0 + far


@pytest.mark.parametrize(("component", "ringing", "far"), COMPONENTS, ids=IDS)
def test_border_response_does_not_depend_on_the_image_size(component, ringing, far):
    # The PSFs above reach a few pixels: near the top-left corner a 32 x 24 image and a
    # 224 x 171 image must filter a hot corner pixel identically, up to the kernel tails that
    # the far borders reflect back.
    small = optics.apply_mtf(hot(SMALL, (0, 0)), [component])
    large = optics.apply_mtf(hot(LARGE, (0, 0)), [component])
    np.testing.assert_allclose(small[:8, :8], large[:8, :8], atol=far * large.max())


def test_motion_along_the_top_border_keeps_its_light_in_the_top_row():
    # A 9 px motion along +x of a hot pixel in the top row: reflection at the top border has
    # nothing to reflect (the motion has no vertical part), so the light stays in row 0 and is
    # all kept, spread over the 9 columns around the hot pixel.
    shape, where = SMALL, (0, 16)
    out = optics.apply_mtf(hot(shape, where), [optics.LinearMotion(9.0, 0.0)])
    assert np.abs(out[1:]).max() < 1e-9
    assert out.sum() == pytest.approx(1.0, abs=1e-4)  # sinc tails cut at the crop
    row = out[0]
    assert row[12:21].sum() == pytest.approx(1.0, abs=0.1)
    assert np.abs(row[:8]).max() < 0.1 * row.max() and np.abs(row[25:]).max() < 0.1 * row.max()


def test_motion_along_the_border_from_a_corner_reflects_instead_of_wrapping():
    shape = SMALL
    out = optics.apply_mtf(hot(shape, (0, 0)), [optics.LinearMotion(9.0, 0.0)])
    # nothing wraps to the right border (beyond the sampled sinc's 1/x tails)
    assert np.abs(out[:, shape[1] // 2:]).max() < 1e-3 * out.max()
    assert out.sum() <= 1.0 + 1e-9
    assert out[0, :6].sum() > 0.5


@pytest.mark.parametrize(("component", "ringing", "far"), COMPONENTS, ids=IDS)
@pytest.mark.parametrize("dtype", [np.float64, np.complex128])
def test_all_zero_image_stays_exactly_zero_with_each_component(component, ringing, far, dtype):
    for shape in (SMALL, (1, 1), (1, 7), (2, 3)):
        out = optics.apply_mtf(np.zeros(shape, dtype=dtype), [component])
        assert out.shape == shape and out.dtype.kind == np.dtype(dtype).kind
        assert np.all(out == 0.0)


@pytest.mark.parametrize(("component", "ringing", "far"), COMPONENTS, ids=IDS)
def test_constant_image_is_unchanged_at_the_border(component, ringing, far):
    # Reflection padding: a uniform radiance stays uniform up to the border (no darkening).
    for shape in (SMALL, (3, 5)):
        out = optics.apply_mtf(np.full(shape, 2.5), [component])
        np.testing.assert_allclose(out, 2.5, rtol=1e-9)


@pytest.mark.parametrize(("component", "ringing", "far"), COMPONENTS, ids=IDS)
def test_hot_pixel_response_is_stable_under_a_tiny_change_of_the_component(
    component, ringing, far
):
    # Each transfer function is smooth in its parameter: 1e-9 relative moves the output by
    # about 1e-9 of its peak (times the parameter's log-derivative, a few units here). The
    # padding grows with the motion length in whole pixels, so a length crossing an integer
    # (5 -> 5 + 5e-9) also moves the sinc tails the crop cuts: the motion kernels get their
    # tail tolerance on top (measured 1.7e-3 of the peak at 30 deg, 2.4e-4 along x).
    fields = {optics.Diffraction: "f_number", optics.PixelAperture: "fill_factor",
              optics.Electronics: "cutoff_cycles_per_px", optics.LinearMotion: "length_px",
              optics.Vibration: "sigma_px"}
    name = fields[type(component)]
    moved = dataclasses.replace(component, **{name: getattr(component, name) * (1 + 1e-9)})
    for where in ((0, 0), (12, 16)):
        a = optics.apply_mtf(hot(SMALL, where), [component])
        b = optics.apply_mtf(hot(SMALL, where), [moved])
        tails = far if isinstance(component, optics.LinearMotion) else 0.0
        assert np.abs(a - b).max() <= (1e-7 + tails) * a.max()


# -------------------------------------------------------------------------------------------
# Point-spread functions wider than the image
# -------------------------------------------------------------------------------------------
WIDE = [optics.Vibration(5.0), optics.LinearMotion(20.0, 0.0), optics.LinearMotion(20.0, 90.0),
        optics.Electronics(0.05)]
WIDE_IDS = ["vibration-5px", "motion-20px-x", "motion-20px-y", "electronics-0.05"]
# A PSF wider than the image once made apply_mtf pad with mode='edge', which repeats a border
# pixel across the whole pad: a hot border pixel came out with up to 6x its light.


@pytest.mark.parametrize("component", WIDE, ids=WIDE_IDS)
def test_wide_psf_on_a_small_image_still_spreads_a_central_hot_pixel_finitely(component):
    # A 20 px box sampled as a sinc rings by up to ~16 % of its height once the reflected
    # copies' tails come in (the Gibbs bound of the box-like components above). Reflection
    # about the border pixel's centre puts each mirror copy half a pixel too close, so a PSF
    # as wide as the image returns slightly more light than leaves it (1.3 % for 5 px).
    out = optics.apply_mtf(hot(SMALL, (12, 16)), [component])
    assert np.all(np.isfinite(out)) and out.min() > -0.25 * out.max()
    assert out.sum() <= 1.02


@pytest.mark.parametrize("component", WIDE, ids=WIDE_IDS)
def test_wide_psf_creates_no_light_from_a_hot_border_pixel_of_a_small_image(component):
    small = optics.apply_mtf(hot(SMALL, (0, 0)), [component])
    large = optics.apply_mtf(hot(LARGE, (0, 0)), [component])
    assert small.sum() <= 1.0 + 1e-3
    # up to the sinc tails that the far border of the small image reflects back (<= 0.6 %)
    np.testing.assert_allclose(small[:8, :8], large[:8, :8], atol=1e-2 * large.max())


@pytest.mark.parametrize("component", [optics.LinearMotion(200.0, 0.0), optics.Electronics(1e-3)],
                         ids=["motion-200px", "electronics-0.001"])
def test_longest_allowed_psf_creates_no_light_on_a_full_size_image(component):
    out = optics.apply_mtf(hot(LARGE, (85, 0)), [component])  # left border, along x
    assert out.sum() <= 1.0 + 1e-3
