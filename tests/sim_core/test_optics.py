"""The MTF chain (seed eq. 33) and the irradiance law (eq. 32)."""

import numpy as np
import pytest

from sim_core import optics

ALL = [
    optics.Diffraction(850e-9, 1.8, 17.5e-6),
    optics.PixelAperture(0.6),
    optics.Electronics(0.4),
    optics.LinearMotion(5.0, 30.0),
    optics.Vibration(1.2),
]


def test_no_components_is_the_identity():
    img = np.random.default_rng(0).random((20, 30))
    assert optics.apply_mtf(img, []) is img


@pytest.mark.parametrize("comp", ALL, ids=lambda c: c.name)
def test_every_component_passes_dc_unchanged(comp):
    assert comp.transfer(np.zeros(1), np.zeros(1))[0] == pytest.approx(1.0)


@pytest.mark.parametrize("where", [(0, 0), (85, 111), (170, 223), (0, 223)])
def test_hot_pixel_keeps_its_energy_and_does_not_wrap(where):
    img = np.zeros((171, 224))
    img[where] = 1.0
    out = optics.apply_mtf(img, ALL)
    r, c = where
    # Light stays near the pixel: nothing appears on the far side of the image.
    far = np.zeros_like(img, dtype=bool)
    far[(r + 85) % 171 if r < 85 else r - 85, :] = True
    far[:, (c + 112) % 224 if c < 112 else c - 112] = True
    assert np.abs(out[far]).max() < 1e-6
    # The box (sinc) components ring, but only a little below zero.
    assert out.min() > -0.02 * out.max()
    if where == (85, 111):  # away from the border, the filter preserves the total light
        assert out.sum() == pytest.approx(1.0, rel=1e-3)  # sampled sinc tails reach the crop


def test_all_zero_image_stays_zero():
    out = optics.apply_mtf(np.zeros((171, 224), dtype=complex), ALL)
    assert np.iscomplexobj(out) and np.all(out == 0)


def test_phasors_mix_linearly_at_an_edge():
    # Left half 1 m, right half 2 m: after the MTF the edge pixels hold a mixture of both
    # phasors, whose phase lies between: a flying pixel.
    f, c = 60.24e6, 299_792_458.0
    ph = np.ones((40, 40), dtype=complex) * np.exp(-4j * np.pi * f * 1.0 / c)
    ph[:, 20:] = np.exp(-4j * np.pi * f * 2.0 / c)
    out = optics.apply_mtf(ph[None], [optics.Vibration(1.5)])[0]
    phase = np.mod(-np.angle(out[20]), 2 * np.pi)
    lo, hi = sorted([4 * np.pi * f / c * 1.0, 4 * np.pi * f / c * 2.0])
    mid = phase[18:22]
    assert np.all((mid > lo + 0.01) & (mid < hi - 0.01))


@pytest.mark.parametrize(("comp", "is_identity"), [
    (optics.Vibration(1e-4), True), (optics.Vibration(1.0), False),
    (optics.Electronics(100.0), True), (optics.PixelAperture(0.6), False),
])
def test_identity_check_up_to_nyquist(comp, is_identity):
    assert (optics.max_deviation_from_identity(comp) < 0.01) == is_identity
