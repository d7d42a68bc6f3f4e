"""The peer paper's mean-variance noise fit (calibration.mean_variance): truth recovered from the
sensor model and from the simulated lab, agreement with the photon transfer fit and with the
EMVA 1288 reference implementation (``emva1288``), clear refusals."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibration.fixtures import BoardFixture, board_object
from calibration.mean_variance import (
    TAP,
    calibrate_mean_variance,
    fit_mean_variance,
    freeman_tukey,
    inverse_freeman_tukey,
)
from calibration.noise_gain import calibrate_noise
from drivers.camera.wire import quantize_frame
from sim_core.errors import InvalidInputError
from sim_core.pipeline import expose_light, render_light
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from sim_core.twin_file import parse_reality
from tests.calibration.test_noise_depth import _stack
from tests.sim_core.scenes import EXAMPLES

#: issue 13's targets
GAIN_REL = 0.05
READ_REL = 0.10


# -- the sensor model's frames ------------------------------------------------------------
@pytest.mark.parametrize(("gain", "read"), [(8.0, 15.0), (17.7, 30.9), (25.0, 50.0),
                                            (40.0, 45.0)])
def test_mean_variance_recovers_gain_and_read_noise_per_tap(gain, read):
    frames = _stack(gain, read, seed=int(gain) + 100)
    res = calibrate_mean_variance([frames])
    assert res.charge == "taps"
    assert res.adc_gain_e_per_dn == pytest.approx(gain, rel=GAIN_REL)
    assert res.read_noise_e == pytest.approx(read, rel=READ_REL)
    assert res.system_gain_dn_per_e == pytest.approx(1.0 / res.adc_gain_e_per_dn)
    # Its own error bars are honest (the truth within 4 standard errors) ...
    assert abs(res.adc_gain_e_per_dn - gain) < 4 * res.gain_std_error + 0.01 * gain
    # ... and it agrees with the photon transfer fit of the differences on the same frames.
    ptc = calibrate_noise([frames])
    assert res.adc_gain_e_per_dn == pytest.approx(ptc.adc_gain_e_per_dn, rel=0.03)
    assert res.read_noise_e == pytest.approx(ptc.read_noise_e, rel=0.06)
    # The paper's polynomial describes the FT-space curve (the paper: RMSE 0.0112).
    assert res.polynomial.degree() == 9 and res.polynomial_rmse < 0.1
    assert res.nonlinearity < 0.06
    assert set(res.summary()) >= {"adc_gain_e_per_dn", "read_noise_e", "dark_signal_dn",
                                  "polynomial_rmse", "charge"}


def test_through_the_wire_the_intensity_is_the_charge():
    """Wire frames carry no taps: the (rounded) intensity is fitted instead."""
    res = calibrate_mean_variance([_stack(12.0, 25.0, n=16, shape=(171, 224))])
    assert res.charge == "intensity"
    assert res.adc_gain_e_per_dn == pytest.approx(12.0, rel=GAIN_REL)
    assert res.read_noise_e == pytest.approx(25.0, rel=READ_REL)


def test_the_fitted_model_makes_noise_of_the_measured_variance():
    """The paper's use of the curve: FT transform, normal draw, back (section 3.4)."""
    res = calibrate_mean_variance([_stack(20.0, 30.0, seed=5)])
    rng = np.random.default_rng(9)
    for level in (60.0, 300.0, 800.0):
        noisy = res.add_noise(np.full(20_000, level), rng)
        want = level / 20.0 + (30.0 / 20.0) ** 2 + 1.0 / 12.0
        assert noisy.mean() == pytest.approx(level, rel=0.01)
        assert noisy.var() == pytest.approx(want, rel=0.08)


def test_freeman_tukey_round_trip_and_stabilisation():
    x = np.array([0.0, 0.5, 3.0, 100.0, 1e5])
    assert inverse_freeman_tukey(freeman_tukey(x)) == pytest.approx(x, abs=1e-9)
    rng = np.random.default_rng(0)
    for lam in (20.0, 200.0, 5000.0):
        assert freeman_tukey(rng.poisson(lam, 200_000)).var() == pytest.approx(1.0, abs=0.03)


# -- the simulated lab's frames --------------------------------------------------------------
@pytest.fixture(scope="module")
def lab_scene():
    """A board at 1 m in the simulated lab with a known sensor."""
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    # A board at 1 m on the axis (the fit lands 8-12 % high on the sequence's own noise view,
    # 200 mm off the axis: it is reported there as a cross-check of the photon transfer).
    board = {"kind": "charuco_board", "squares_x": 5, "squares_y": 7, "square_m": 0.10,
             "marker_m": 0.06}
    obj = board_object(board, BoardFixture("tilt+30", 30.0, centre_height_m=0.16), spec)
    spec = spec.model_copy(update={"objects": [o for o in spec.objects if not o.on_turntable]
                                   + [obj]})
    truth = {"adc_gain_e_per_dn": 14.3, "read_noise_e": 37.0}
    reality = parse_reality({"camera": {"sensor": truth}})
    scene = build_scene(spec, EXAMPLES, turntable_deg=10.0, solar_suns=0.0, twin=reality)
    return truth, scene


def _lab_frames(scene, render_seed):
    """24 frames of one render (the render's seed moves the pixels' jitter, so which pixels
    are bright, dark or mixed; the sensor noise's seeds stay the same)."""
    settings = RenderSettings(integrator="direct", spp=4, seed=render_seed)
    rendered = render_light(scene, RenderRequest(settings))
    return [expose_light(scene, rendered, noise_rng=np.random.default_rng([7, i])).raw
            for i in range(24)]


# The wire's estimate has a standard error of about 2.4 % (gain) and 4 % (read noise) on this
# view: 24 frames of some 3,200 usable pixels' intensities; the taps' about 0.5 %.
@pytest.mark.parametrize("render_seed", [3, *(pytest.param(s, marks=pytest.mark.slow)
                                              for s in range(4, 11))])
def test_the_simulated_lab_gives_gain_and_read_noise(lab_scene, render_seed):
    truth, scene = lab_scene
    frames = _lab_frames(scene, render_seed)
    taps = calibrate_mean_variance([frames])
    wire = calibrate_mean_variance([[quantize_frame(f, "MODE_5_45FPS_500") for f in frames]])
    assert (taps.charge, wire.charge) == ("taps", "intensity")
    for res in (taps, wire):
        assert res.adc_gain_e_per_dn == pytest.approx(truth["adc_gain_e_per_dn"], rel=GAIN_REL)
        assert res.read_noise_e == pytest.approx(truth["read_noise_e"], rel=READ_REL)
        # The board's bright pixels are in the linear range (SBI starts at 2,550 DN here).
        assert res.mean_range_dn[1] > 300.0
        # Its error bars are honest.
        assert abs(res.adc_gain_e_per_dn - truth["adc_gain_e_per_dn"]) < 4 * res.gain_std_error
    # The taps hold 2 % (16 charge values per pixel), the intensity 5 %.
    assert taps.adc_gain_e_per_dn == pytest.approx(truth["adc_gain_e_per_dn"], rel=0.02)


# -- the EMVA 1288 reference implementation ----------------------------------------------------
def _flat_field(k_dn_per_e, read_e, seed, levels_e, n=2, shape=(48, 48), offset_dn=40.0):
    """An EMVA 1288 camera: flat illumination, Poisson electrons, read noise, 12-bit ADC with a
    black level, ``n`` frames per level; the dark stack first."""
    rng = np.random.default_rng(seed)

    def frames(mu_e):
        e = rng.poisson(mu_e, (n, *shape)) + rng.normal(0.0, read_e, (n, *shape))
        return np.clip(np.round(offset_dn + k_dn_per_e * e), 0, 4095)

    return frames(0.0), [frames(mu) for mu in levels_e]


def _emva(dark, bright, levels_e):
    from emva1288.process import Data1288, Results1288
    from emva1288.process.routines import get_int_imgs

    def temporal(imgs):
        d = get_int_imgs(imgs.astype(np.int64))
        return {"sum": np.sum(d["sum"]), "pvar": np.sum(d["pvar"]), "dmean": d["dmean"]}

    texp = 1.0
    data = {"height": dark.shape[1], "width": dark.shape[2],
            "temporal": {texp: {0.0: temporal(dark[:2]),
                                **{float(p): temporal(b[:2]) for p, b in zip(levels_e, bright,
                                                                             strict=True)}}},
            "spatial": {texp: {0.0: get_int_imgs(dark.astype(np.int64)),
                               float(levels_e[-1]): get_int_imgs(bright[-1].astype(np.int64))}}}
    res = Results1288(Data1288(data, loglevel=logging.WARNING).data, loglevel=logging.WARNING)
    return float(res.K), float(res.sigma_d)


@pytest.fixture
def numpy_1_api(monkeypatch):
    """emva1288 1.0.2 calls ``np.asfarray``, removed in NumPy 2.0."""
    if not hasattr(np, "asfarray"):
        monkeypatch.setattr(np, "asfarray", lambda a: np.asarray(a, dtype=np.float64),
                            raising=False)


@pytest.mark.parametrize(("k", "read", "seed"), [(0.1, 20.0, 1), (0.04, 30.0, 2),
                                                 (0.25, 8.0, 3)])
def test_agrees_with_the_emva1288_reference(numpy_1_api, k, read, seed):
    """Both fits on the same two-frame pairs (EMVA 1288's temporal measurement): each within
    3 % (gain) and 10 % (read noise) of the truth, and within 4 % / 10 % of each other."""
    levels = np.geomspace(300.0, 0.6 * 4000.0 / k, 14)
    dark, bright = _flat_field(k, read, seed, levels)
    emva_k, emva_read = _emva(dark, bright, levels)
    ours = fit_mean_variance(bright, model=TAP, dark=dark, linear_share=1.0)
    assert ours.system_gain_dn_per_e == pytest.approx(k, rel=0.03)
    assert emva_k == pytest.approx(k, rel=0.03)
    assert ours.system_gain_dn_per_e == pytest.approx(emva_k, rel=0.04)
    assert ours.read_noise_e == pytest.approx(read, rel=READ_REL)
    assert emva_read == pytest.approx(read, rel=READ_REL)
    assert ours.read_noise_e == pytest.approx(emva_read, rel=0.10)
    # The dark image (the paper subtracts it) is EMVA's mu_y.dark: the black level here.
    assert ours.dark_signal_dn == pytest.approx(40.0, abs=0.2)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(k=st.floats(0.02, 0.5), read=st.floats(2.0, 60.0), seed=st.integers(0, 2**32 - 1),
       n=st.integers(2, 6))
def test_any_valid_stack_gives_a_positive_finite_gain(k, read, seed, n):
    """Any stack: a positive, finite gain or a refusal naming the field, nothing else; where
    the shot noise is seen (at the top level at least 4x the read noise's variance) and the fit
    gives a gain, within 25 % even from 2 frames of 24 x 24 pixels."""
    levels = np.geomspace(200.0, 0.5 * 4000.0 / k, 8)
    dark, bright = _flat_field(k, read, seed, levels, n=n, shape=(24, 24))
    shot_seen = 2000.0 * k >= 4.0 * (k * read) ** 2
    try:
        res = fit_mean_variance(bright, model=TAP, dark=dark, linear_share=1.0)
    except InvalidInputError as e:
        # A refusal names the stacks, never a wrong number. (Small stacks, 2-6 frames of
        # 24 x 24 pixels, are refused now and then even where the shot noise is seen: the
        # binned curve's slope comes out negative.)
        assert e.field == "stacks"
        return
    assert np.isfinite(res.adc_gain_e_per_dn) and res.adc_gain_e_per_dn > 0
    assert np.isfinite(res.read_noise_e) and res.read_noise_e >= 0
    if shot_seen:
        assert res.adc_gain_e_per_dn == pytest.approx(1.0 / k, rel=0.25)


# -- refusals --------------------------------------------------------------------------------
def test_bad_stacks_are_refused_naming_the_field():
    frames = _stack(10.0, 20.0, n=3)
    with pytest.raises(InvalidInputError, match=r"stacks\[0\].*too short.*at least 2"):
        calibrate_mean_variance([frames[:1]])
    with pytest.raises(InvalidInputError, match=r"stacks\[1\].*too short"):
        fit_mean_variance([np.ones((4, 100)), np.ones((1, 100))])
    bad = np.full((4, 200), 50.0)
    bad[2, 3] = np.nan
    with pytest.raises(InvalidInputError, match=r"stacks\[0\]: 1 non-finite.*must be finite"):
        fit_mean_variance([bad])
    # Everything saturated: nothing usable.
    sat = [f.__class__(**{**f.__dict__, "saturated": np.ones_like(f.saturated)})
           for f in frames]
    with pytest.raises(InvalidInputError, match=r"stacks: only 0 of .* unsaturated"):
        calibrate_mean_variance([sat])
    # A variance that does not grow with the mean (constant noise, no shot noise).
    rng = np.random.default_rng(1)
    flat = [100.0 * (i + 1) + rng.normal(0, 2.0, (8, 500)) for i in range(6)]
    flat = [np.clip(f - 40.0 * (i + 1) + 3.0 * (5 - i) * rng.normal(0, 1.0, f.shape), 1, None)
            for i, f in enumerate(flat)]
    with pytest.raises(InvalidInputError, match=r"does not grow with the mean.*must be > 0"):
        fit_mean_variance(flat)
    with pytest.raises(InvalidInputError, match=r"degree: 30: must be an integer from 1 to 15"):
        calibrate_mean_variance([frames], degree=30)
    with pytest.raises(InvalidInputError, match=r"too narrow a range|too few|only"):
        fit_mean_variance([np.full((8, 500), 300.0) + rng.normal(0, 4.0, (8, 500))])
