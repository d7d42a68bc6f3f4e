"""Grey as shown to people: stretched to the 1st-99th percentile of the valid amplitude, with a
colour bar whose ends state that range."""

from __future__ import annotations

import io

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image

from sim_core.preview import (
    GREY_DISPLAY_PERCENTILES,
    ColourScale,
    colour_bar_png,
    colour_bar_ticks,
    grey_colours,
    grey_scale,
)

amplitudes = arrays(np.float64, (6, 7), elements=st.one_of(
    st.floats(0.0, 4096.0), st.just(np.nan), st.just(np.inf)))


@settings(max_examples=60, deadline=None)
@given(amp=amplitudes, valid=arrays(np.bool_, (6, 7)))
def test_the_grey_range_is_the_valid_percentiles_and_never_empty(amp, valid):
    scale = grey_scale((amp, valid))
    assert np.isfinite(scale.lo) and np.isfinite(scale.hi) and scale.hi > scale.lo
    assert scale.unit == "DN" and scale.label_ends
    chosen = amp[valid & np.isfinite(amp)]
    if chosen.size:
        lo, hi = np.percentile(chosen, GREY_DISPLAY_PERCENTILES)
        if hi > lo:
            assert (scale.lo, scale.hi) == (lo, hi)
        else:  # a flat image is widened so that the bar has a span
            assert (scale.lo, scale.hi) == (lo - 0.5, hi + 0.5)
        assert scale.note == "1st-99th pct of valid pixels"


def test_two_images_share_one_range():
    gen = np.random.default_rng(0)
    dim, bright = gen.uniform(10, 20, (8, 8)), gen.uniform(40, 60, (8, 8))
    ok = np.ones((8, 8), bool)
    both = grey_scale((dim, ok), (bright, ok))
    lo, hi = np.percentile(np.concatenate([dim.ravel(), bright.ravel()]), [1, 99])
    assert (both.lo, both.hi) == (lo, hi)
    # the brighter image is brighter on screen
    assert grey_colours(bright, both).mean() > grey_colours(dim, both).mean()


def test_without_valid_pixels_the_finite_ones_count_and_without_those_zero_to_one():
    amp = np.array([[1.0, 2.0, np.nan]])
    none = np.zeros(amp.shape, bool)
    s = grey_scale((amp, none))
    assert (s.lo, s.hi) == tuple(np.percentile([1.0, 2.0], [1, 99]))
    assert "no valid pixel" in s.note
    empty = grey_scale((np.full((2, 2), np.nan), np.ones((2, 2), bool)))
    assert (empty.lo, empty.hi) == (0.0, 1.0)


@settings(max_examples=40, deadline=None)
@given(lo=st.floats(0.0, 1000.0), span=st.floats(0.5, 3000.0))
def test_the_range_maps_to_black_and_white_and_is_clipped(lo, span):
    scale = ColourScale("gray", lo, lo + span, "DN", label_ends=True)
    rgb = grey_colours(np.array([[lo - 1.0, lo, lo + span, lo + span + 1.0, np.nan]]), scale)
    assert rgb[0, :, 0].tolist() == [0, 0, 255, 255, 0]


def test_the_colour_bar_states_the_range_at_its_ends():
    scale = ColourScale("gray", 15.0412, 55.0634, "DN", "1st-99th pct", label_ends=True)
    ticks = colour_bar_ticks(scale)
    assert [t for _, t in ticks] == ["15.04", "35.05", "55.06"]
    assert ticks[0][0] == scale.lo and ticks[-1][0] == scale.hi
    png = Image.open(io.BytesIO(colour_bar_png(scale, scale.label("grey"), 300, 56)))
    assert png.size == (300, 56)
    bar = np.asarray(png.convert("L"))
    row = bar[int(0.35 * 56)]  # through the bar: dark on the left, light on the right
    assert row[40] < 60 and row[260] > 200
    assert colour_bar_ticks(ColourScale("gray", 0.0, 1.0, "DN")) == ()  # matplotlib's own
