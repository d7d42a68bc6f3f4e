"""The rig calibration's verdict rules, each on constructed evidence (no rig, no renders)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from scipy import ndimage

from calibration.board_detection import refine_saddle, saddle_std_px
from calibration.depth import DepthView, fit_depth_errors
from calibration.noise_gain import tap_difference_variance_dn2
from calibration.photometry import fit_source_power, region_agreement
from calibration.rig_verdicts import (
    CameraTurntableEvidence,
    DepthEvidence,
    StageEvidence,
    calibration_keys,
    camera_turntable_verdicts,
    distortion_limit,
    jackknife_std,
    reduced_chi2,
    rig_verdicts,
    unexplained_views,
)
from calibration.verdicts import CHI2_UNEXPLAINED, chi2_limit_for
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.twin_file import CalibrationFile

FINITE = st.floats(min_value=-1e6, max_value=1e6)
EDGE = st.sampled_from([0.0, math.nan, math.inf, -1.0])


# -- the written file's keys ------------------------------------------------------------------
def test_every_written_key_is_listed_and_a_grid_of_offsets_is_one_key():
    # as written: a coefficient at its default (0) is left out of the file, so it has no key
    cal = CalibrationFile.model_validate({
        "camera": {"fx_px": 210.0, "distortion": {"k1": -0.1, "k2": 0.01, "p1": 1e-4,
                                                  "p2": 0.0, "k3": 0.0},
                   "depth": {"phase_offset_rad": [0.01],
                             "pixel_offset_m": {"grid_step_px": 64,
                                                "offsets_mm": [[0.0] * 5] * 4}},
                   "sensor": {"adc_gain_e_per_dn": 9.0}},
        "turntable": {"zero_offset_deg": 0.3},
        "provenance": {"created_utc": "now", "rig": "r", "software": "s", "frames_used": 1}})
    assert calibration_keys(cal) == [
        "camera.fx_px", "camera.distortion.k1", "camera.distortion.k2", "camera.distortion.p1",
        "camera.depth.phase_offset_rad",
        "camera.depth.pixel_offset_m", "camera.sensor.adc_gain_e_per_dn",
        "turntable.zero_offset_deg"]


def test_a_key_the_sequence_writes_but_does_not_judge_is_an_error_not_a_gap():
    ev = CameraTurntableEvidence(StageEvidence(1.0, "stage"), std={}, fx_px=200, fy_px=200)
    depth = DepthEvidence(StageEvidence(1.0, "depth"), [1e-3], 1e-4, [60.24e6], (1, 2), (0.5, 1),
                          1.0)
    with pytest.raises(ValueError, match=r"no verdict for illumination\.power_w"):
        rig_verdicts(["camera.fx_px", "illumination.power_w"], ev, depth, {})


# -- goodness of fit --------------------------------------------------------------------------
def test_reduced_chi2_of_pure_noise_is_one_and_of_a_model_error_above_the_limit():
    rng = np.random.default_rng(1)
    s = np.full(20000, 0.05)
    assert reduced_chi2(rng.normal(0, 0.05, s.size), s, n_params=10) == pytest.approx(1, abs=0.03)
    # a residual twice the noise: chi-square 4, unexplained
    assert reduced_chi2(rng.normal(0, 0.1, s.size), s) > CHI2_UNEXPLAINED


@given(r=st.lists(st.one_of(FINITE, EDGE), min_size=0, max_size=8),
       s=st.lists(st.one_of(st.floats(min_value=0, max_value=1e3), EDGE), min_size=0,
                  max_size=8), p=st.integers(0, 10))
def test_reduced_chi2_is_safe_at_its_edges(r, s, p):
    n = min(len(r), len(s))
    out = reduced_chi2(np.array(r[:n]), np.array(s[:n]), p)
    assert out == math.inf or (math.isfinite(out) and out >= 0)


def test_few_degrees_of_freedom_raise_the_limit_by_the_chi_square_s_own_noise():
    assert chi2_limit_for(7) == pytest.approx(3.47, abs=0.01)
    assert chi2_limit_for(10_000) == CHI2_UNEXPLAINED
    assert chi2_limit_for(0) == math.inf
    # 8 white squares agreeing to chance (2.16 happens 3.5 % of the time): explained
    v = StageEvidence(2.16, "squares", dof=7).judged(0.01, 0.03)
    assert v.determined
    assert StageEvidence(2.16, "many").judged(0.01, 0.03).verdict == "unexplained"


# -- views the model cannot explain ------------------------------------------------------------
def test_a_few_unexplained_views_are_dropped_many_blame_the_model():
    chi2 = {f"v{i}": 1.0 for i in range(20)} | {"bad": 30.0, "nan": math.nan}
    bad, droppable = unexplained_views(chi2)
    assert bad == ["nan", "bad"] and droppable  # worst first: not finite is the worst
    bad, droppable = unexplained_views({f"v{i}": 5.0 for i in range(8)} | {"ok": 1.0})
    assert len(bad) == 8 and not droppable


def test_views_not_explained_make_their_keys_unexplained_and_are_named():
    stage = StageEvidence(1.1, "the joint adjustment", unexplained=("tilt0@+30", "tilt0@+35"))
    v = stage.judged(0.01, 1.0)
    assert v.verdict == "unexplained" and "tilt0@+30, tilt0@+35" in v.reason


# -- spread over fixtures ---------------------------------------------------------------------
def test_jackknife_of_identical_estimates_is_zero_and_of_one_group_unbounded():
    assert jackknife_std([1.0, 1.0, 1.0]).tolist() == [0.0]
    assert jackknife_std([2.0]).tolist() == [math.inf]


def test_jackknife_recovers_the_standard_error_of_a_mean():
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1.0, 400)
    leave_one_out = [(x.sum() - xi) / (x.size - 1) for xi in x]
    assert jackknife_std(leave_one_out)[0] == pytest.approx(x.std(ddof=1) / 20, rel=1e-6)


def test_the_spread_over_fixtures_wins_over_an_optimistic_jacobian():
    stage = StageEvidence(1.0, "stage")
    ev = CameraTurntableEvidence(stage, std={"cx_px": 0.05, "zero_offset_deg": 0.01},
                                 spread={"cx_px": 0.8}, fx_px=210, fy_px=210)
    out = camera_turntable_verdicts(ev, [])
    assert out["camera.cx_px"].verdict == "not determined" and out["camera.cx_px"].std == 0.8
    assert out["turntable.zero_offset_deg"].determined
    # an unknown parameter has no standard deviation: not determined, never determined
    assert out["camera.fx_px"].verdict == "not determined"


def test_a_residual_above_the_noise_scales_the_jacobian_s_error():
    stage = StageEvidence(1.69, "stage")
    ev = CameraTurntableEvidence(stage, std={"zero_offset_deg": 0.05}, fx_px=210, fy_px=210)
    v = camera_turntable_verdicts(ev, [])["turntable.zero_offset_deg"]
    assert v.determined and v.std == pytest.approx(0.065)


def test_k3_held_at_zero_is_not_determined_and_says_why():
    ev = CameraTurntableEvidence(StageEvidence(1.0, "s"), std={"k1": 1e-4}, fx_px=210,
                                 fy_px=210)
    out = camera_turntable_verdicts(ev, ["k1", "k3"])
    assert out["camera.distortion.k1"].determined
    assert out["camera.distortion.k3"].verdict == "not determined"
    assert "held at 0" in out["camera.distortion.k3"].reason


def test_the_axis_std_is_in_the_world_frame_and_zero_along_the_axis():
    ev = CameraTurntableEvidence(StageEvidence(1.0, "s"),
                                 std={"point_u": 3e-3, "point_v": 1e-4, "axis_u": 1e-4,
                                      "axis_v": 1e-4},
                                 basis=np.array([[1.0, 0, 0], [0, 1.0, 0]]), fx_px=210,
                                 fy_px=210)
    out = camera_turntable_verdicts(ev, [])
    point = out["turntable.axis_point_m"]
    assert point.verdict == "not determined" and point.std == pytest.approx([3e-3, 1e-4, 0.0])
    assert out["turntable.axis_direction"].determined


@given(radius=st.one_of(st.floats(min_value=0, max_value=5), EDGE),
       fx=st.one_of(st.floats(min_value=0, max_value=1e4), EDGE))
def test_a_distortion_limit_is_never_a_division_error(radius, fx):
    lim = distortion_limit("k1", fx if math.isfinite(fx) else 1.0,
                           radius if math.isfinite(radius) else 0.0)
    assert lim > 0


def test_the_distortion_limit_moves_the_image_corner_by_the_reprojection_target():
    # k1 r^3 f = 0.3 px at r = 0.6, f = 210 px
    assert distortion_limit("k1", 210.0, 0.6) * 210.0 * 0.6**3 == pytest.approx(0.3)


# -- the corners' noise -----------------------------------------------------------------------
def _saddle_image(size=31, x0=15.3, y0=14.8, blur=1.2):
    yy, xx = np.mgrid[:size, :size].astype(float)
    u, v = (xx - x0) / blur, (yy - y0) / blur
    return 0.5 + 0.5 * np.tanh(u) * np.tanh(v), (x0, y0)


def test_the_saddle_std_predicts_the_scatter_of_refined_corners():
    img, (x0, y0) = _saddle_image()
    sigma = 0.02
    rng = np.random.default_rng(5)
    pts = []
    for _ in range(400):
        p, ok = refine_saddle(img + rng.normal(0, sigma, img.shape), np.array([[15.0, 15.0]]))
        assert ok[0]
        pts.append(p[0])
    scatter = np.std(pts, axis=0)
    predicted = saddle_std_px(img, np.array([[x0, y0]]), np.full(img.shape, sigma))[0]
    # bilinear resampling averages neighbours: the prediction is an upper bound, not far above
    assert np.all(predicted >= 0.9 * scatter) and np.all(predicted <= 2.5 * scatter)


def test_no_saddle_or_no_contrast_has_an_unbounded_corner_std():
    flat = np.full((31, 31), 0.5)
    out = saddle_std_px(flat, np.array([[15.0, 15.0], [0.0, 0.0]]), np.full(flat.shape, 0.01))
    assert np.all(np.isinf(out))
    img, (x0, y0) = _saddle_image()
    out = saddle_std_px(img, np.array([[x0, y0]]), np.full(img.shape, np.inf))
    assert np.all(np.isinf(out))


@given(i=st.one_of(st.floats(min_value=-1e3, max_value=1e6), EDGE))
def test_the_tap_difference_variance_never_falls_below_read_and_quantisation_noise(i):
    v = tap_difference_variance_dn2(np.array([i]), 9.0, 30.0)[0]
    assert math.isfinite(v) and v >= 2 * 30.0**2 / 81.0 + 1 / 6 - 1e-12


def test_a_gain_that_cannot_be_divided_by_is_refused_by_name():
    with pytest.raises(Exception, match="adc_gain_e_per_dn"):
        tap_difference_variance_dn2(np.ones(2), 0.0, 30.0)
    with pytest.raises(Exception, match="read_noise_e"):
        tap_difference_variance_dn2(np.ones(2), 9.0, math.nan)


# -- the depth fit against the phase noise ----------------------------------------------------
def _depth_views(n_views=6, sigma_rad=0.01, excess=1.0, seed=0):
    """Board views with an offset and one harmonic; the phases' scatter ``excess`` times the
    noise the views claim (what a model error the fit cannot take up looks like to it)."""
    rng = np.random.default_rng(seed)
    f = 60.24e6
    k = 4 * np.pi * f / SPEED_OF_LIGHT_M_S
    views = []
    for i in range(n_views):
        rng_m = np.full((40, 50), 0.6 + 0.1 * i) + np.linspace(0, 0.05, 50)[None, :]
        phi = k * rng_m
        meas = phi + 0.03 + 0.01 * np.sin(2 * phi + 0.4) + rng.normal(0, excess * sigma_rad,
                                                                       phi.shape)
        views.append(DepthView(f"v{i}", meas[None], np.full(phi.shape, 100.0), rng_m,
                               np.ones(phi.shape, bool), np.full((1, *phi.shape), sigma_rad)))
    return views, f


def test_a_depth_fit_of_noise_only_is_explained_and_of_a_larger_scatter_is_not():
    views, f = _depth_views()
    good = fit_depth_errors(views, [f])
    assert good.reduced_chi2 == pytest.approx(1.0, abs=0.1)
    assert all(math.isfinite(s) and s > 0 for s in good.model_std_rad)
    assert 0 < good.pixel_offset_std_m < 0.01
    views, f = _depth_views(excess=2.0)
    assert fit_depth_errors(views, [f]).reduced_chi2 > CHI2_UNEXPLAINED


def test_a_depth_fit_without_the_noise_reports_no_chi_square():
    views, f = _depth_views()
    bare = [DepthView(v.name, v.phase_rad, v.amplitude, v.true_range_m, v.mask) for v in views]
    out = fit_depth_errors(bare, [f])
    assert math.isnan(out.reduced_chi2) and out.model_std_rad == ()


# -- the source power's squares ---------------------------------------------------------------
def _squares(offsets, noise=0.01, seed=0):
    rng = np.random.default_rng(seed)
    pred = np.zeros((60, 80))
    for i in range(len(offsets)):
        r, c = divmod(i, 4)
        pred[5 + 15 * r: 15 + 15 * r, 5 + 18 * c: 17 + 18 * c] = 100.0
    meas = pred * (1 + rng.normal(0, noise, pred.shape))
    for i, off in enumerate(offsets):
        r, c = divmod(i, 4)
        meas[5 + 15 * r: 15 + 15 * r, 5 + 18 * c: 17 + 18 * c] *= 1 + off
    return meas, pred


def test_white_squares_that_agree_are_explained_and_a_shading_error_is_not():
    meas, pred = _squares([0.0] * 8)
    res = fit_source_power(meas, pred, 1.0)
    assert res.n_regions == 8 and res.regions_reduced_chi2 < chi2_limit_for(7)
    meas, pred = _squares([0.0, 0.05, -0.05, 0.0, 0.05, -0.05, 0.0, 0.02])
    res = fit_source_power(meas, pred, 1.0)
    assert res.regions_reduced_chi2 > 10 * chi2_limit_for(7)
    assert res.regions_std_error > res.ratio_std_error


def test_regions_of_identical_values_are_no_division_by_zero():
    use = np.zeros((10, 30), bool)
    use[2:8, 2:10] = True
    use[2:8, 15:25] = True
    n, chi2, se, dof = region_agreement(np.ones(use.shape), use, 1.0)
    assert n == 2 and chi2 == 0.0 and se == 0.0 and dof == 1
    # a mode would leave no degree of freedom: it is not fitted
    n, chi2, se, dof = region_agreement(np.ones(use.shape), use, 1.0, [np.ones(use.shape)])
    assert n == 2 and chi2 == 0.0 and dof == 1
    one = use.copy()
    one[:, 12:] = False
    n, chi2, se, dof = region_agreement(np.ones(use.shape), one, 1.0)
    assert n == 1 and math.isnan(chi2) and math.isnan(se) and dof == 0


def _blurred_board(shift_px: float, gradient: float = 0.0) -> np.ndarray:
    """A board of 8 white squares under a lamp's fall-off, blurred by the optics (sigma 1.2
    px), its image moved right by ``shift_px`` (a quarter pixel's steps), times a vertical
    gradient of ``gradient`` over the image (unmodelled stray light's kind of shading)."""
    up = 4
    r, c = np.mgrid[0: 60 * up, 0: 80 * up] / up
    white = np.zeros(r.shape, bool)
    for i in range(8):
        row, col = divmod(i, 4)
        white |= ((r >= 6 + 24 * row) & (r < 24 + 24 * row)
                  & (c >= 4 + 19 * col - shift_px) & (c < 18 + 19 * col - shift_px))
    falloff = 1.0 - 0.4 * ((c - 20) ** 2 + (r - 30) ** 2) / 2500.0
    img = ndimage.gaussian_filter(np.where(white, 100.0, 4.0) * falloff, 1.2 * up)
    img = img.reshape(60, up, 80, up).mean(axis=(1, 3))
    return img * (1.0 + gradient * (np.arange(60)[:, None] - 30) / 30)


def test_a_calibrated_image_shift_is_fitted_out_and_stray_shading_is_not():
    """The twin's image a fifth of a pixel off (a calibration within its error bars): the
    squares disagree beyond their noise until the prediction's shift modes are fitted out;
    a vertical gradient (unexplained shading) stays unexplained with them."""
    rng = np.random.default_rng(3)
    pred = _blurred_board(0.0)
    modes = [_blurred_board(0.25) - pred]
    noise = rng.normal(0.0, 0.05, pred.shape)
    meas = _blurred_board(-0.25) + noise
    plain = fit_source_power(meas, pred, 1.0)
    fitted = fit_source_power(meas, pred, 1.0, image_shift_modes=modes)
    assert plain.regions_reduced_chi2 > chi2_limit_for(plain.regions_dof)
    assert fitted.regions_dof == plain.regions_dof - 1
    assert fitted.regions_reduced_chi2 < chi2_limit_for(fitted.regions_dof)
    assert fitted.power_w == plain.power_w  # the estimate is the pixels' median either way
    shaded = fit_source_power(_blurred_board(0.0, gradient=0.01) + noise, pred, 1.0,
                              image_shift_modes=modes)
    assert shaded.regions_reduced_chi2 > chi2_limit_for(shaded.regions_dof)


def test_a_key_predicted_through_a_gain_that_is_not_determined_claims_no_more_than_it():
    from calibration.rig_evidence import through_gain
    from calibration.verdicts import Verdict

    power = Verdict("determined", 0.002)
    bad_gain = Verdict("unexplained", 0.01, "the photon transfer line: reduced chi-square 1.43e+03")
    out = through_gain(power, bad_gain)
    assert out.verdict == "unexplained" and out.std == 0.002
    assert "camera.sensor.adc_gain_e_per_dn" in out.reason and "1.43e+03" in out.reason
    assert through_gain(power, Verdict("not determined", None, "too few bins")).verdict == (
        "not determined")
    # a determined gain leaves the key's own verdict, and a key not determined stays so
    assert through_gain(power, Verdict("determined", 0.01)) is power
    own = Verdict("unexplained", 0.002, "its squares disagree")
    assert through_gain(own, bad_gain) is own


def test_the_depth_keys_claim_nothing_while_the_drift_they_are_fitted_without_is_unexplained():
    from calibration.rig_evidence import depth_through_drift
    from calibration.verdicts import Verdict, Verdicts
    from calibration.warmup import DRIFT_KEY

    depth = {"camera.depth.phase_offset_rad": Verdict("determined", 0.03),
             "camera.depth.wiggling": Verdict("determined", 0.03),
             "camera.fx_px": Verdict("determined", 0.1)}
    out = depth_through_drift(Verdicts({**depth, DRIFT_KEY: Verdict(
        "unexplained", 0.01, "the warm-up sequence: reduced chi-square 3.01")}))
    assert out["camera.depth.phase_offset_rad"].verdict == "unexplained"
    assert DRIFT_KEY in out["camera.depth.wiggling"].reason
    assert out["camera.fx_px"].determined  # not fitted through the drift
    # no drift above the noise: the depth keys keep their own verdicts
    calm = depth_through_drift(Verdicts({**depth, DRIFT_KEY: Verdict(
        "not determined", None, "no drift above the noise")}))
    assert calm["camera.depth.phase_offset_rad"].determined
    assert depth_through_drift(Verdicts(depth))["camera.depth.wiggling"].determined


@given(st.floats(0.0, 10.0), st.floats(-30.0, 30.0), st.sampled_from([[60.24e6],
                                                                      [80.32e6, 60.24e6]]))
@example(1e-300, 5e-324, [60.24e6])  # a rise so small its product underflows (CI found it)
@example(10.0, -30.0, [80.32e6, 60.24e6])
def test_the_drift_coefficients_error_carried_into_the_depth_model_is_safe_and_linear(
        std_mm_per_c, rise_c, freqs):
    from calibration.rig_evidence import drift_carried_std_rad

    out = drift_carried_std_rad(freqs, [std_mm_per_c], rise_c)
    assert len(out) == len(freqs) and all(v >= 0.0 and math.isfinite(v) for v in out)
    # range error s * |rise| as phase: 4 pi f d / c
    for f, v in zip(freqs, out, strict=True):
        assert v == pytest.approx(4 * math.pi * f * 1e-3 * std_mm_per_c * abs(rise_c)
                                  / SPEED_OF_LIGHT_M_S, rel=1e-12, abs=1e-300)
    # an unknown coefficient error carries as unbounded, except for views at the reference
    assert drift_carried_std_rad(freqs, [math.nan], rise_c) == (
        [0.0] * len(freqs) if rise_c == 0.0 else [math.inf] * len(freqs))
    assert drift_carried_std_rad(freqs, [std_mm_per_c], math.nan) == [math.inf] * len(freqs)


def test_the_depth_models_std_takes_the_drifts_error_in_quadrature():
    from types import SimpleNamespace

    from calibration.rig_evidence import depth_evidence

    depth = SimpleNamespace(per_view_reduced_chi2={"v": 1.0}, reduced_chi2=1.0,
                            model_std_rad=(0.003, 0.004), pixel_offset_std_m=1e-4,
                            phase_span_rad=(0.1, 0.5), range_span_m=(0.4, 0.9), coverage=1.0)
    alone = depth_evidence(depth, [80.32e6, 60.24e6])
    assert list(alone.model_std_rad) == [0.003, 0.004]
    carried = depth_evidence(depth, [80.32e6, 60.24e6], [0.004, 0.003])
    assert list(carried.model_std_rad) == pytest.approx([0.005, 0.005])
    # one offset for both frequencies: it takes the larger drift term, never none
    one = SimpleNamespace(**{**depth.__dict__, "model_std_rad": (0.003,)})
    assert list(depth_evidence(one, [80.32e6, 60.24e6], [0.004, 0.001]).model_std_rad) == \
        pytest.approx([0.005])
