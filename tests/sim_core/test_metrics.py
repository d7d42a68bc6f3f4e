"""Tests of sim_core.metrics: the indexes of seed Table 5 and the chi-square of the SLIM paper."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from sim_core.errors import InvalidInputError
from sim_core.frame_io import depth_preview_mm, grey_preview_8bit
from sim_core.metrics import (
    DEPTH_DATA_RANGE,
    GREY_DATA_RANGE,
    TABLE_HEADER,
    ChannelMetrics,
    ComparisonReport,
    chi_square_distance,
    compare_images,
    depth_16bit,
    depth_mm_16bit,
    effective_mask,
    grey_8bit,
    grey_histogram,
    mask_by_depth_window,
    mask_by_region,
    mask_from_objects,
    masked_mse,
    masked_ssim,
    pearson_chi_square,
    psnr_db,
    relative_error,
    tof_figures,
)
from sim_core.tof import ToFImage

H, W = 24, 32


def frame(amplitude: np.ndarray, range_m: np.ndarray, valid: np.ndarray | None = None) -> ToFImage:
    """A ToFImage with the given amplitude and range (NaN where not valid, as reconstruct does)."""
    amplitude = np.asarray(amplitude, dtype=np.float64)
    range_m = np.asarray(range_m, dtype=np.float64)
    if valid is None:
        valid = np.isfinite(range_m)
    rng = np.where(valid, range_m, np.nan)
    return ToFImage(
        range_m=rng,
        depth_z_m=0.9 * rng,
        amplitude=amplitude,
        intensity=2.0 * amplitude,
        phase_rad=np.zeros((1, *amplitude.shape)),
        valid=np.asarray(valid, dtype=bool),
        frequencies_hz=np.array([80.32e6]),
    )


def random_frame(seed: int) -> ToFImage:
    """Amplitude in [0, 200] (grey = amplitude with full scale 255), range in [0.5, 2] m."""
    gen = np.random.default_rng(seed)
    amp = np.round(gen.uniform(0.0, 200.0, (H, W)))
    rng = np.round(gen.uniform(0.5, 2.0, (H, W)), 3)
    return frame(amp, rng)


# ------------------------------------------------------------------------------------------
# The seed's own numbers (ToF seed, Sect. 3, Table 5)
# ------------------------------------------------------------------------------------------

# (reported MSE, half-width of its last printed digit, data range, reported PSNR, tolerance)
SEED_PSNR = [
    pytest.param(1782.60, 0.005, 255.0, 15.62, 0.005, id="grey-ours"),
    pytest.param(4.45e5, 0.005e5, 65535.0, 39.85, 0.005, id="depth-ours"),
    pytest.param(5.46e5, 0.005e5, 65535.0, 38.95, 0.005, id="depth-ref22"),
    # 10 log10(255^2 / 1788.35) = 15.606, printed 15.60: truncated rather than rounded in the
    # seed, so only agreement to 0.01 dB can be asked for this cell.
    pytest.param(1788.35, 0.005, 255.0, 15.60, 0.01, id="grey-ref22"),
]


@pytest.mark.parametrize(("mse", "half_digit", "data_range", "reported", "tol"), SEED_PSNR)
def test_seed_table5_psnr_follows_from_its_mse(mse, half_digit, data_range, reported, tol):
    lo = psnr_db(mse + half_digit, data_range)
    hi = psnr_db(mse - half_digit, data_range)
    assert lo - tol <= reported <= hi + tol


@pytest.mark.parametrize(
    ("measured", "simulated", "reported_percent"),
    [
        pytest.param(17.79, 18.25, 2.59, id="grey-mean-ours"),
        pytest.param(17.79, 16.73, 5.96, id="grey-mean-ref22"),
        pytest.param(1411.67, 1358.06, 3.80, id="grey-var-ours"),
        pytest.param(1411.67, 1347.53, 4.54, id="grey-var-ref22"),
        pytest.param(403.04, 476.75, 18.29, id="depth-mean-ours"),
        pytest.param(403.04, 750.28, 86.16, id="depth-mean-ref22"),
        pytest.param(2.95e5, 3.38e5, 14.58, id="depth-var-ours"),
        pytest.param(2.95e5, 4.15e5, 40.68, id="depth-var-ref22"),
    ],
)
def test_seed_table5_relative_errors_follow_from_its_means_and_variances(
    measured, simulated, reported_percent
):
    assert 100.0 * relative_error(measured, simulated) == pytest.approx(reported_percent, abs=0.005)


def test_table_rows_reproduce_seed_table5_layout():
    def channel(name, mm, ms, vm, vs, mse, ssim, rng):
        return ChannelMetrics(
            name=name,
            unit="u",
            data_range=rng,
            mean_measured=mm,
            mean_simulated=ms,
            var_measured=vm,
            var_simulated=vs,
            mse=mse,
            ssim=ssim,
            psnr_db=psnr_db(mse, rng),
            rel_err_mean=relative_error(mm, ms),
            rel_err_var=relative_error(vm, vs),
        )

    report = ComparisonReport(
        grey=channel("grey", 17.79, 18.25, 1411.67, 1358.06, 1782.60, 0.72, 255.0),
        depth=channel("depth", 403.04, 476.75, 2.95e5, 3.38e5, 4.45e5, 0.85, 65535.0),
        grey_chi_square=0.0123,
        chi_square_bins=256,
        n_pixels=100,
        grey_full_scale_measured=1.0,
        grey_full_scale_simulated=1.0,
        depth_unit_m=1e-3,
        depth_source="range",
    )
    rows = report.table_rows()
    assert len(TABLE_HEADER) == 5
    assert rows[0] == ("Grey", "Mean", "17.79", "18.25", "2.59%")
    assert rows[1] == ("Grey", "Var", "1411.67", "1358.06", "3.80%")
    assert rows[2][1:4] == ("MSE", "—", "1782.60")
    assert rows[4][1:4] == ("PSNR", "—", "15.62")
    assert rows[5] == ("Depth", "Mean", "403.04", "476.75", "18.29%")
    assert rows[6] == ("Depth", "Var", "2.95e+05", "3.38e+05", "14.58%")
    assert rows[7][3] == "4.45e+05"
    assert rows[9][3] == "39.85"
    assert rows[10] == ("Grey", "Chi-square", "—", "0.0123", "—")


# ------------------------------------------------------------------------------------------
# Conversions (reused from frame_io)
# ------------------------------------------------------------------------------------------


def test_depth_mm_16bit_is_frame_io_convention():
    rng = np.array([[1.2346, np.nan], [70.0, -1.0]])
    out = depth_mm_16bit(rng)
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, [[1235, 0], [65535, 0]])
    np.testing.assert_array_equal(out, depth_preview_mm(rng))
    np.testing.assert_array_equal(depth_16bit(rng), out)
    np.testing.assert_array_equal(depth_16bit(np.array([1.2346]), 1e-4), [12346])


def test_grey_8bit_uses_the_given_full_scale():
    amp = np.array([[0.0, 0.25, 1.0, 2.0, np.nan, -1.0]])
    out = grey_8bit(amp, 1.0)
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, [[0, 64, 255, 255, 0, 0]])
    np.testing.assert_array_equal(out, grey_preview_8bit(amp, np.isfinite(amp), 1.0)[0])
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(InvalidInputError) as exc:
            grey_8bit(amp, bad)
        assert exc.value.field == "full_scale"


# ------------------------------------------------------------------------------------------
# Masks
# ------------------------------------------------------------------------------------------


def test_mask_by_depth_window_is_closed_and_rejects_nan():
    rng = np.array([0.4, 0.5, 1.0, 1.5, 1.6, np.nan])
    np.testing.assert_array_equal(mask_by_depth_window(rng, 0.5, 1.5), [0, 1, 1, 1, 0, 0])
    with pytest.raises(InvalidInputError) as exc:
        mask_by_depth_window(rng, 1.0, 1.0)
    assert exc.value.field == "far_m"


def test_mask_by_region_is_a_half_open_rectangle():
    m = mask_by_region((4, 5), (1, 3), (2, 5))
    assert m.dtype == np.bool_
    assert m.sum() == 2 * 3
    assert m[1, 2] and m[2, 4] and not m[3, 2] and not m[1, 1]
    for rows, cols, field in (((0, 5), (0, 1), "rows"), ((0, 1), (3, 3), "cols")):
        with pytest.raises(InvalidInputError) as exc:
            mask_by_region((4, 5), rows, cols)
        assert exc.value.field == field


def test_mask_from_objects_selects_ids():
    obj = np.array([[-1, 0, 1], [2, 1, -1]], dtype=np.int32)
    np.testing.assert_array_equal(mask_from_objects(obj, [1, 2]), [[0, 0, 1], [1, 1, 0]])
    with pytest.raises(InvalidInputError) as exc:
        mask_from_objects(obj.astype(float), [1])
    assert exc.value.field == "object_id"
    with pytest.raises(InvalidInputError) as exc:
        mask_from_objects(obj, [])
    assert exc.value.field == "ids"


def test_effective_mask_intersects_both_valid_masks():
    a, b = random_frame(1), random_frame(2)
    va = np.ones((H, W), bool)
    va[0, 0] = False
    vb = np.ones((H, W), bool)
    vb[1, 1] = False
    user = np.ones((H, W), bool)
    user[2, 2] = False
    eff = effective_mask(user, frame(a.amplitude, a.range_m, va), frame(b.amplitude, b.range_m, vb))
    assert eff.sum() == H * W - 3
    assert not (eff[0, 0] or eff[1, 1] or eff[2, 2])


# ------------------------------------------------------------------------------------------
# The figures a ToF engineer reads: depth difference, flying and invalid pixels
# ------------------------------------------------------------------------------------------


def step_with_mixed_column(offset_m: float = 0.0, mixed: bool = True) -> np.ndarray:
    """Columns < 12 at 1 m, > 12 at 2 m (plus ``offset_m``); column 12 mixed (1.5 m) or on the
    background."""
    r = np.full((H, W), 2.0)
    r[:, :12] = 1.0
    r[:, 12] = 1.5 if mixed else 2.0
    return r + offset_m


def test_a_known_offset_and_known_flying_pixels_give_known_figures():
    """Simulated = measured + 5 mm, except that the measured frame has a column of mixed pixels
    (flying) and four invalid pixels; the simulated edge is clean."""
    amp = np.full((H, W), 100.0)
    valid = np.ones((H, W), bool)
    valid[0, :4] = False
    meas = frame(amp, step_with_mixed_column(), valid)
    sim = frame(amp, step_with_mixed_column(0.005, mixed=False))
    rep = compare_images(meas, sim, None, grey_full_scale=255.0)
    tof = rep.tof
    assert tof.mask_pixels == H * W
    assert tof.flying_share_measured == pytest.approx(H / (H * W))
    assert tof.flying_share_simulated == 0.0
    assert tof.invalid_share_measured == pytest.approx(4 / (H * W))
    assert tof.invalid_share_simulated == 0.0
    assert tof.depth_diff_n_pixels == H * W - H - 4
    assert tof.depth_diff_median_mm == pytest.approx(5.0)
    assert tof.depth_diff_mad_mm == pytest.approx(0.0, abs=1e-9)
    assert tof.depth_diff_p95_abs_mm == pytest.approx(5.0)
    # near the edge the mixed column is 1 pixel in 9 (500 mm off): left in, it would be the 95th
    # percentile
    near_edge = tof_figures(meas, sim, mask_by_region((H, W), (0, H), (8, 17)))
    assert near_edge.depth_diff_n_pixels == H * 8
    assert near_edge.depth_diff_p95_abs_mm == pytest.approx(5.0)
    d = rep.to_dict()["tof"]
    assert d["depth_diff_median_mm"] == pytest.approx(5.0)
    assert d["flying_rule"]["near_threshold_m"] == 0.018
    json.dumps(d, allow_nan=False)
    # swapped, the difference changes sign and the shares swap
    back = compare_images(sim, meas, None, grey_full_scale=255.0).tof
    assert back.depth_diff_median_mm == pytest.approx(-5.0)
    assert back.flying_share_simulated == tof.flying_share_measured
    assert back.invalid_share_simulated == tof.invalid_share_measured


def test_the_figures_are_over_the_mask_and_say_why_pixels_are_left_out():
    amp = np.full((H, W), 100.0)
    meas = frame(amp, step_with_mixed_column())
    sim = frame(amp, step_with_mixed_column(-0.002))
    # a mask on the background only: no flying pixel in it, 2 mm nearer
    tof = tof_figures(meas, sim, mask_by_region((H, W), (0, H), (14, W)))
    assert tof.mask_pixels == H * (W - 14)
    assert tof.flying_share_measured == tof.flying_share_simulated == 0.0
    assert tof.depth_diff_median_mm == pytest.approx(-2.0)
    # a mask on the mixed column only: every pixel is flying in both, none left to compare
    only = tof_figures(meas, sim, mask_by_region((H, W), (0, H), (12, 13)))
    assert only.flying_share_measured == only.flying_share_simulated == 1.0
    assert only.depth_diff_n_pixels == 0
    assert only.depth_diff_median_mm is None and only.depth_diff_p95_abs_mm is None
    assert "no pixel valid in both frames" in only.summary_lines()[0]
    # the depth along the optical axis (0.9 x range in these frames) when asked
    z = tof_figures(meas, sim, mask_by_region((H, W), (0, H), (14, W)), depth_source="z")
    assert z.depth_diff_median_mm == pytest.approx(-1.8)
    with pytest.raises(InvalidInputError, match="mask"):
        tof_figures(meas, sim, np.zeros((H, W), bool))
    with pytest.raises(InvalidInputError, match="depth_source"):
        tof_figures(meas, sim, None, depth_source="x")


@settings(max_examples=40, deadline=None)
@given(offset_mm=st.floats(-500.0, 500.0), tilt=st.floats(-0.05, 0.05),
       seed=st.integers(0, 2**16))
def test_a_constant_offset_is_the_median_with_no_spread(offset_mm, tilt, seed):
    gen = np.random.default_rng(seed)
    xx = np.mgrid[0:H, 0:W][1]
    rng = 1.5 + tilt * (xx - W / 2) / W + gen.normal(0.0, 0.003, (H, W))
    amp = np.full((H, W), 100.0)
    tof = tof_figures(frame(amp, rng), frame(amp, rng + offset_mm / 1e3), None)
    assert tof.depth_diff_n_pixels == H * W
    assert tof.depth_diff_median_mm == pytest.approx(offset_mm, abs=1e-6)
    assert tof.depth_diff_mad_mm == pytest.approx(0.0, abs=1e-6)
    assert tof.depth_diff_p95_abs_mm == pytest.approx(abs(offset_mm), abs=1e-6)


# ------------------------------------------------------------------------------------------
# compare_images
# ------------------------------------------------------------------------------------------


def test_identical_images_are_a_perfect_match():
    f = random_frame(3)
    rep = compare_images(f, f, None, grey_full_scale=255.0)
    for ch in (rep.grey, rep.depth):
        assert ch.mse == 0.0
        assert ch.ssim == 1.0
        assert ch.psnr_db == math.inf
        assert ch.rel_err_mean == 0.0 and ch.rel_err_var == 0.0
    assert rep.grey_chi_square == 0.0
    assert rep.n_pixels == H * W
    d = rep.to_dict()
    assert d["grey"]["psnr_db"] == "inf"
    json.dumps(d, allow_nan=False)
    assert ("Grey", "PSNR", "—", "inf", "—") in rep.table_rows()


def test_known_offset_gives_known_mse_and_table_quantities():
    meas = random_frame(4)
    sim = frame(meas.amplitude + 5.0, meas.range_m + 0.007)
    rep = compare_images(meas, sim, None, grey_full_scale=255.0)
    assert rep.grey.mse == pytest.approx(25.0)
    assert rep.depth.mse == pytest.approx(49.0)
    assert rep.grey.mean_simulated - rep.grey.mean_measured == pytest.approx(5.0)
    assert rep.grey.var_simulated == pytest.approx(rep.grey.var_measured)
    assert rep.grey.data_range == GREY_DATA_RANGE and rep.depth.data_range == DEPTH_DATA_RANGE
    assert rep.grey.psnr_db == pytest.approx(10 * math.log10(255.0**2 / 25.0))
    assert rep.depth.unit == "mm"
    assert rep.depth.rel_err_mean == pytest.approx(7.0 / rep.depth.mean_measured)


def test_changing_an_excluded_pixel_changes_nothing():
    meas, sim = random_frame(5), random_frame(6)
    mask = mask_by_region((H, W), (4, 20), (5, 28))
    base = compare_images(meas, sim, mask, grey_full_scale=255.0).to_dict()
    for r, c in ((0, 0), (10, 2), (21, 15), (12, 30)):  # outside the rectangle
        amp = sim.amplitude.copy()
        rng = sim.range_m.copy()
        amp[r, c] = 250.0
        rng[r, c] = 9.0
        changed = compare_images(meas, frame(amp, rng), mask, grey_full_scale=255.0)
        assert changed.to_dict() == base
    # with the default full scale (a percentile of the measured amplitude inside the mask) an
    # excluded measured pixel changes nothing either, even if it becomes the brightest one
    auto = compare_images(meas, sim, mask).to_dict()
    amp = meas.amplitude.copy()
    amp[0, 0] = 1e6
    assert compare_images(frame(amp, meas.range_m), sim, mask).to_dict() == auto
    # a pixel invalid in the measured frame is excluded although inside the rectangle
    valid = meas.valid.copy()
    valid[10, 10] = False
    meas_inv = frame(meas.amplitude, meas.range_m, valid)
    ref = compare_images(meas_inv, sim, mask, grey_full_scale=255.0)
    amp = sim.amplitude.copy()
    amp[10, 10] = 0.0
    assert compare_images(meas_inv, frame(amp, sim.range_m), mask, grey_full_scale=255.0) == ref
    assert ref.n_pixels == 16 * 23 - 1
    # and a pixel inside the mask does matter
    amp[12, 12] = 250.0 if amp[12, 12] < 100 else 0.0
    assert compare_images(meas, frame(amp, sim.range_m), mask, grey_full_scale=255.0) != base


def test_ssim_and_psnr_agree_with_scikit_image_on_a_full_mask():
    meas, sim = random_frame(7), random_frame(8)
    rep = compare_images(meas, sim, None, grey_full_scale=255.0)
    gm, gs = grey_8bit(meas.amplitude, 255.0), grey_8bit(sim.amplitude, 255.0)
    dm, ds = depth_mm_16bit(meas.range_m), depth_mm_16bit(sim.range_m)
    assert rep.grey.ssim == pytest.approx(structural_similarity(gm, gs, data_range=255), 1e-12)
    assert rep.depth.ssim == pytest.approx(structural_similarity(dm, ds, data_range=65535), 1e-12)
    assert rep.grey.psnr_db == pytest.approx(peak_signal_noise_ratio(gm, gs, data_range=255))
    assert rep.depth.psnr_db == pytest.approx(peak_signal_noise_ratio(dm, ds, data_range=65535))
    full = np.ones((H, W), bool)
    assert masked_mse(gm, gs, full) == pytest.approx(np.mean((gm - gs.astype(float)) ** 2))


def test_grey_full_scale_default_and_pair():
    meas = random_frame(9)
    rep = compare_images(meas, meas, None)
    expected = float(np.percentile(meas.amplitude, 99.5))
    assert rep.grey_full_scale_measured == rep.grey_full_scale_simulated == expected
    # simulated frame in another amplitude unit: a pair of full scales makes them identical
    sim = frame(meas.amplitude * 1000.0, meas.range_m)
    rep2 = compare_images(meas, sim, None, grey_full_scale=(255.0, 255e3))
    assert rep2.grey.mse == 0.0 and rep2.grey_chi_square == 0.0


def test_depth_source_z_uses_depth_along_the_axis():
    meas, sim = random_frame(10), random_frame(11)
    rep = compare_images(meas, sim, None, grey_full_scale=255.0, depth_source="z")
    dm, ds = depth_mm_16bit(meas.depth_z_m), depth_mm_16bit(sim.depth_z_m)
    assert rep.depth.mean_measured == pytest.approx(dm.mean())
    assert rep.depth.mse == pytest.approx(np.mean((dm.astype(float) - ds) ** 2))


def test_masked_ssim_of_a_mask_inside_the_border_strip_still_works():
    gen = np.random.default_rng(12)
    a, b = gen.uniform(0, 255, (H, W)), gen.uniform(0, 255, (H, W))
    mask = np.zeros((H, W), bool)
    mask[0, :] = True  # entirely within the 3-pixel strip scikit-image drops
    assert -1.0 <= masked_ssim(a, b, mask, 255.0) <= 1.0


# ------------------------------------------------------------------------------------------
# Bad input
# ------------------------------------------------------------------------------------------


def test_bad_input_names_the_field():
    meas = random_frame(13)
    small = frame(np.zeros((H, W - 1)), np.ones((H, W - 1)))
    cases = [
        ((meas, small, None), {}, "simulated.range_m", "differs"),
        ((meas, meas, np.zeros((H, W), bool)), {}, "mask", "none is valid"),
        ((meas, meas, np.ones((H, W), dtype=np.uint8)), {}, "mask", "bool"),
        ((meas, meas, np.ones((H, W + 1), bool)), {}, "mask", "shape"),
        ((meas, meas, None), {"grey_full_scale": -1.0}, "grey_full_scale", "> 0"),
        ((meas, meas, None), {"grey_full_scale": (1.0, 0.0)}, "grey_full_scale[1]", "> 0"),
        ((meas, meas, None), {"depth_unit": 0.0}, "depth_unit", "> 0"),
        ((meas, meas, None), {"depth_source": "x"}, "depth_source", "'z'"),
        ((meas, meas, None), {"chi_square_bins": 0}, "chi_square_bins", "1..256"),
    ]
    for args, kwargs, field, text in cases:
        with pytest.raises(InvalidInputError) as exc:
            compare_images(*args, **kwargs)
        assert exc.value.field == field
        assert text in str(exc.value)
    tiny = frame(np.ones((5, 5)), np.ones((5, 5)))
    with pytest.raises(InvalidInputError) as exc:
        compare_images(tiny, tiny, None, grey_full_scale=1.0)
    assert "7 x 7" in str(exc.value)
    dark = frame(np.zeros((H, W)), np.ones((H, W)))
    with pytest.raises(InvalidInputError) as exc:
        compare_images(dark, dark, None)
    assert exc.value.field == "grey_full_scale"


def test_psnr_and_relative_error_edge_cases():
    assert psnr_db(0.0, 255.0) == math.inf
    with pytest.raises(InvalidInputError):
        psnr_db(-1.0, 255.0)
    with pytest.raises(InvalidInputError):
        psnr_db(1.0, 0.0)
    assert relative_error(0.0, 0.0) == 0.0
    assert relative_error(0.0, 1.0) == math.inf
    assert relative_error(-2.0, -1.0) == 0.5


# ------------------------------------------------------------------------------------------
# Chi-square (SLIM paper Sect. 10, Eq. (16))
# ------------------------------------------------------------------------------------------


def test_pearson_chi_square_is_the_slim_formula():
    f = np.array([10.0, 20.0, 0.0, 70.0])
    p = np.array([0.2, 0.2, 0.1, 0.5])
    n = f.sum()
    expected = sum((fk - n * pk) ** 2 / (n * pk) for fk, pk in zip(f, p, strict=True))
    assert pearson_chi_square(f, p) == pytest.approx(expected)
    assert pearson_chi_square(f, f) == 0.0
    assert pearson_chi_square(f, np.array([0.0, 1.0, 0.0, 1.0])) == math.inf
    assert pearson_chi_square(np.array([0.0, 5.0]), np.array([0.0, 1.0])) == 0.0


def test_chi_square_distance_is_the_pooled_two_sample_slim_statistic():
    gen = np.random.default_rng(14)
    n = 500
    a = np.bincount(gen.integers(0, 10, n), minlength=12).astype(float)
    b = np.bincount(gen.integers(2, 12, n), minlength=12).astype(float)
    pooled = (a + b) / (2 * n)
    two_sample = pearson_chi_square(a, pooled) + pearson_chi_square(b, pooled)
    assert two_sample == pytest.approx(2 * n * chi_square_distance(a, b))
    assert chi_square_distance(np.array([1.0, 0.0]), np.array([0.0, 3.0])) == 1.0


def test_grey_histogram_is_normalised_over_the_mask():
    img = np.array([[0, 0, 255], [128, 1, 1]], dtype=np.uint8)
    mask = np.array([[True, True, True], [True, False, False]])
    h = grey_histogram(img, mask, 256)
    assert h.sum() == pytest.approx(1.0)
    assert h[0] == 0.5 and h[255] == 0.25 and h[128] == 0.25 and h[1] == 0.0
    assert grey_histogram(img, mask, 2).tolist() == [0.5, 0.5]


# ------------------------------------------------------------------------------------------
# Properties
# ------------------------------------------------------------------------------------------

small_images = arrays(np.uint8, (9, 11), elements=st.integers(0, 255))
histograms = arrays(np.float64, 16, elements=st.sampled_from([0.0, 0.0, 0.0, 1.0, 3.0, 1e6]))


@settings(max_examples=40, deadline=None)
@given(a=small_images, b=small_images)
def test_mse_symmetric_and_ssim_at_most_one(a, b):
    mask = np.ones(a.shape, bool)
    mask[0, :3] = False
    assert masked_mse(a, b, mask) == masked_mse(b, a, mask)
    s = masked_ssim(a, b, mask, 255.0)
    assert s <= 1.0 + 1e-12
    assert s == pytest.approx(masked_ssim(b, a, mask, 255.0), abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(p=histograms, q=histograms)
def test_chi_square_symmetric_nonnegative_finite_with_empty_bins(p, q):
    if p.sum() == 0 or q.sum() == 0:
        with pytest.raises(InvalidInputError):
            chi_square_distance(p, q)
        return
    d = chi_square_distance(p, q)
    assert math.isfinite(d)
    assert 0.0 <= d <= 1.0 + 1e-12
    assert d == pytest.approx(chi_square_distance(q, p), abs=1e-15)
    assert chi_square_distance(p, p) == 0.0
