"""The unexplained residual's shapes: synthetic residual images against their noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.edges import object_edge_mask
from sim_core.errors import InvalidInputError
from sim_core.unexplained import (
    MIN_PIXELS,
    MIN_SHARE,
    dark_next_to_bright,
    image_thirds,
    locate_excess,
)

H, W = 171, 224
SIGMA_MM = 2.0


def scene() -> dict[str, np.ndarray]:
    """A body (bright disc) between two darker panels, on nothing: masks and an amplitude."""
    yy, xx = np.mgrid[:H, :W]
    body = (yy - 85) ** 2 + (xx - 112) ** 2 < 40**2
    left = (abs(yy - 85) < 12) & (xx > 20) & (xx < 70)
    right = (abs(yy - 85) < 12) & (xx > 154) & (xx < 204)
    amplitude = np.where(body, 1.0, 0.0) + np.where(left | right, 0.6, 0.0)
    # a dark ring at the body's rim, next to its bright middle (where stray light weighs most)
    rim = body & ((yy - 85) ** 2 + (xx - 112) ** 2 > 33**2)
    amplitude[rim] = 0.08
    mask = body | left | right
    object_id = np.select([body, left, right], [0, 1, 2], default=-1)
    return {"body": body, "panel_left": left, "panel_right": right, "mask": mask,
            "amplitude": amplitude, "object_id": object_id, "rim": rim}


S = scene()
EDGES = object_edge_mask(S["object_id"]) & S["mask"]
DARK = dark_next_to_bright(S["amplitude"], S["mask"])


def noise(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, SIGMA_MM, (H, W))


def locate(residual: np.ndarray, n: np.ndarray | None = None, **kw):
    return locate_excess(residual, noise(99) if n is None else n, S["mask"], unit="mm",
                         overall="the turntable objects",
                         regions={k: S[k] for k in ("body", "panel_left", "panel_right")},
                         sets={"edges": EDGES, "dark": DARK}, **kw)


def top(loc):
    assert loc.named(), loc.to_dict()
    return loc.named()[0]


def test_the_scene_has_edges_and_dark_pixels_next_to_bright_ones():
    assert 100 < EDGES.sum() < 0.5 * S["mask"].sum()
    assert DARK.sum() > 100 and (DARK & ~S["rim"]).sum() < 0.2 * DARK.sum()


@pytest.mark.parametrize("seed", range(5))
def test_a_residual_of_noise_alone_is_within_the_noise(seed):
    loc = locate(noise(seed))
    assert loc.components == (), loc.to_dict()
    text = loc.text()
    assert text == "within the noise" or text.startswith("no shape stands out of the noise"), text
    if loc.excess_ms <= 0.0:
        assert text == "within the noise"


def test_a_common_range_offset_is_named_with_its_value():
    loc = locate(noise(1) + 3.2)
    c = top(loc)
    assert (c.shape, c.where) == ("offset", "the turntable objects")
    assert c.mean == pytest.approx(3.2, abs=0.1) and c.share > 0.9
    assert loc.text().startswith("a common offset of +3.1")
    assert "mm over the turntable objects (" in loc.text()


def test_an_offset_on_one_object_names_the_object():
    r = noise(2) + np.where(S["panel_left"], -5.0, 0.0)
    c = top(locate(r))
    assert (c.shape, c.where) == ("object", "panel_left")
    # the common offset the panel drags along is taken out first, the panel's own is the rest
    assert -5.2 < c.mean < -4.0 and c.share > 0.6
    assert "an offset of -4." in locate(r).text() and "mm on panel_left" in locate(r).text()


def test_excess_at_silhouette_edges_is_named_as_such():
    sign = np.where(np.random.default_rng(3).random((H, W)) < 0.5, -1.0, 1.0)
    r = noise(3) + np.where(EDGES, 12.0 * sign, 0.0)
    c = top(locate(r))
    assert c.shape == "edges" and c.where == "silhouette edges"
    assert c.share > 0.8 and c.rms > 3.0 * c.noise_rms
    assert "two-signed" in locate(r).text()  # light moved both ways: motion, not a haze


def test_stray_light_on_dark_pixels_next_to_bright_ones_is_named_as_such():
    r = noise(4) + np.where(DARK, 6.0, 0.0)
    loc = locate(r)
    shapes = [c.shape for c in loc.named()]
    assert "dark" in shapes, loc.to_dict()
    dark = next(c for c in loc.named() if c.shape == "dark")
    assert dark.share > 0.5
    assert "dark pixels next to bright ones" in loc.text()
    assert "one-signed, mean +" in loc.text()  # a haze brightens (here: lengthens) one way


def test_excess_on_one_object_whatever_its_sign_names_the_object():
    sign = np.where(np.random.default_rng(8).random((H, W)) < 0.5, -1.0, 1.0)
    r = noise(8) + np.where(S["panel_right"] & ~EDGES, 8.0 * sign, 0.0)
    c = top(locate(r))
    assert (c.shape, c.where) == ("on_object", "panel_right") and c.share > 0.8
    assert "excess on panel_right: " in locate(r).text()


def test_an_object_s_offset_is_not_named_again_as_its_excess():
    loc = locate(noise(9) + np.where(S["panel_left"], -5.0, 0.0))
    assert ("on_object", "panel_left") not in [(c.shape, c.where) for c in loc.components]


def test_excess_in_one_part_of_the_image_names_that_part():
    thirds = image_thirds((H, W))
    r = noise(5) + np.where(thirds["middle left"], 9.0 * np.sin(np.arange(W) / 2.0), 0.0)
    c = top(locate(r))
    assert (c.shape, c.where) == ("region", "the middle left of the image")


def test_a_spread_excess_is_unexplained_without_a_shape():
    loc = locate(noise(6) * 2.0)
    assert loc.named() == ()
    assert loc.text().startswith("spread over the compared pixels")


@settings(max_examples=30)
@given(scale=st.floats(1e-6, 1e6), offset=st.floats(-10.0, 10.0), seed=st.integers(0, 2**16))
def test_the_shapes_do_not_depend_on_the_unit(scale, offset, seed):
    """Every threshold is the noise's: rescaling residual and noise keeps shapes and shares."""
    r = noise(seed) + offset
    a, b = locate(r), locate(r * scale, noise(99) * scale)
    assert [c.shape for c in a.components] == [c.shape for c in b.components]
    for ca, cb in zip(a.components, b.components, strict=True):
        assert cb.share == pytest.approx(ca.share, rel=1e-6)
        assert cb.mean == pytest.approx(ca.mean * scale, rel=1e-6)


@settings(max_examples=40)
@given(value=st.floats(-1e3, 1e3), noise_value=st.sampled_from([0.0, 1e-300, 1.0]),
       n_nan=st.integers(0, H * W))
def test_degenerate_images_give_finite_figures_or_a_clear_error(value, noise_value, n_nan):
    """Constant images, a noise-free pair (identical captures) and mostly-NaN images."""
    r = np.full((H, W), value)
    r.ravel()[:n_nan] = np.nan
    n = np.full((H, W), noise_value)
    try:
        loc = locate(r, n)
    except InvalidInputError as exc:
        assert exc.field == "mask"
        return
    d = loc.to_dict()
    assert all(math.isfinite(v) for v in (d["residual_rms"], d["noise_rms"], d["excess_ms"]))
    assert all(math.isfinite(c["share"]) for c in d["components"])
    if noise_value == 0.0:  # no noise scale: nothing can be told apart from it
        assert d["components"] == []


def test_bad_input_names_the_field_and_the_allowed_range():
    r = noise(0)
    with pytest.raises(InvalidInputError) as exc:
        locate_excess(r, r[:-1], S["mask"], unit="mm")
    assert exc.value.field == "noise"
    with pytest.raises(InvalidInputError) as exc:
        locate_excess(r, r, S["mask"], unit="mm", z=0.0)
    assert exc.value.field == "z"
    few = np.zeros((H, W), bool)
    few.ravel()[: MIN_PIXELS - 1] = True
    with pytest.raises(InvalidInputError, match=f"at least {MIN_PIXELS}") as exc:
        locate_excess(r, r, few, unit="mm")
    assert exc.value.field == "mask"
    with pytest.raises(InvalidInputError) as exc:
        object_edge_mask(S["amplitude"])
    assert exc.value.field == "object_id"
    with pytest.raises(InvalidInputError) as exc:
        dark_next_to_bright(S["amplitude"], S["mask"], radius_px=0.0)
    assert exc.value.field == "radius_px"
    with pytest.raises(InvalidInputError) as exc:
        dark_next_to_bright(S["amplitude"], S["mask"], ratio=1.0)
    assert exc.value.field == "ratio"


def test_only_shares_of_at_least_the_minimum_are_named():
    loc = locate(noise(7) + 3.0 + np.where(S["panel_right"], 0.8, 0.0))
    assert all(c.share >= MIN_SHARE for c in loc.named())
    assert len(loc.named()) <= len(loc.components)
