"""Gain, read noise and depth errors recovered from frames made by the real models."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.depth import DepthView, fit_depth_errors
from calibration.noise_gain import (
    calibrate_noise,
    steepest_gradient,
    successive_difference_dof,
    successive_difference_variance,
)
from drivers.camera.wire import quantize_frame
from sim_core.camera import F_60_24_MHZ, Intrinsics
from sim_core.depth_errors import DepthErrorModel, range_to_phase_rad
from sim_core.errors import InvalidInputError
from sim_core.scene import Camera
from sim_core.sensor import PixelElectrons, SensorParams, expose
from sim_core.tof import phase_from_phasor
from sim_core.twin_file import DepthErrors, PixelOffsetPattern, WigglingTerm


def _stack(gain, read, n=24, seed=0, shape=(60, 80)):
    rng = np.random.default_rng(seed)
    cam = Camera(Intrinsics(shape[1], shape[0], 50.0, 50.0, 40.0, 30.0), np.eye(4))
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]]
    active = 200.0 + 60_000.0 * (c / shape[1]) * (0.3 + 0.7 * ((r // 10 + c // 10) % 2))
    e = PixelElectrons(active=active, ambient=np.zeros(shape), dark=1.0,
                       phasor=(0.6 * active * np.exp(-1j * 2.0))[None])
    sensor = SensorParams(adc_gain_e_per_dn=gain, read_noise_e=read)
    return [quantize_frame(expose(e, cam, sensor, rng), "MODE_5_45FPS_500")
            for _ in range(n)] if shape == (171, 224) else [
        expose(e, cam, sensor, rng) for _ in range(n)]


@pytest.mark.parametrize(("gain", "read"), [(8.0, 15.0), (17.7, 30.9), (25.0, 50.0),
                                            (40.0, 45.0)])
def test_photon_transfer_recovers_gain_and_read_noise(gain, read):
    res = calibrate_noise([_stack(gain, read, seed=int(gain))])
    assert res.adc_gain_e_per_dn == pytest.approx(gain, rel=0.05)
    assert res.read_noise_e == pytest.approx(read, rel=0.10)
    assert res.method == "differences"


def test_through_the_wire_too():
    """Frames quantised as the camera's wire delivers them (12-bit words, no taps)."""
    res = calibrate_noise([_stack(12.0, 25.0, n=16, shape=(171, 224))])
    assert res.adc_gain_e_per_dn == pytest.approx(12.0, rel=0.05)
    assert res.read_noise_e == pytest.approx(25.0, rel=0.10)


def test_stacks_that_cannot_give_a_variance_are_refused():
    frames = _stack(10.0, 20.0, n=3)
    with pytest.raises(InvalidInputError, match="too short for a variance"):
        calibrate_noise([frames[:1]])
    flat = [f.__class__(**{**f.__dict__, "intensity": np.full_like(f.intensity, 30.0)})
            for f in frames]
    with pytest.raises(InvalidInputError, match=r"too few|too narrow"):
        calibrate_noise([flat])


def _depth_views(truth, seed, n_views=40, noise_rad=0.003, shape=(60, 80)):
    """Board views: planes at ranges 0.76-1.28 m tilted across the image, with the errors."""
    rng = np.random.default_rng(seed)
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]]
    views = []
    for i in range(n_views):
        base = rng.uniform(0.8, 1.2)
        true = base + 0.08 * rng.uniform(-1, 1) * (c - shape[1] / 2) / shape[1] \
            + 0.05 * rng.uniform(-1, 1) * (r - shape[0] / 2) / shape[0]
        phasor = np.exp(-1j * range_to_phase_rad(true, F_60_24_MHZ))[None]
        measured = phase_from_phasor(truth.apply_to_phasor(phasor))
        measured = measured + rng.normal(0, noise_rad, measured.shape)
        mask = np.zeros(shape, dtype=bool)
        x0 = rng.integers(0, shape[1] // 2)
        mask[5:-5, x0 : x0 + shape[1] // 2] = True
        views.append(DepthView(f"v{i}", measured, np.full(shape, 100.0), true, mask))
    return views


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_depth_errors_are_recovered_over_the_range_seen(seed):
    rng = np.random.default_rng(seed)
    spec = DepthErrors(
        phase_offset_rad=[float(rng.uniform(-0.1, 0.1))],
        wiggling=[WigglingTerm(harmonic=int(rng.integers(2, 5)), amplitude_rad=0.038,
                               phase_rad=float(rng.uniform(-3, 3)))],
        pixel_offset_m=PixelOffsetPattern(sigma=0.004, correlation_px=float(rng.uniform(8, 20)),
                                          seed=seed))
    truth = DepthErrorModel.from_spec(spec, [F_60_24_MHZ], (60, 80))
    res = fit_depth_errors(_depth_views(truth, seed), [F_60_24_MHZ])
    fitted = DepthErrorModel.from_spec(res.depth_errors, [F_60_24_MHZ], (60, 80))
    # The model's residual over the phases and pixels the views saw.
    phi = np.linspace(*res.phase_span_rad, 50)[:, None, None] * np.ones((1, 60, 80))
    seen = np.zeros((60, 80), bool)
    seen[5:-5, :] = True
    diff = np.concatenate([(fitted.phase_error_rad(p, 0) - truth.phase_error_rad(p, 0))[seen]
                           for p in phi])
    rms_mm = np.sqrt(np.mean(diff**2)) / range_to_phase_rad(1.0, F_60_24_MHZ) * 1e3
    assert rms_mm < 2.0
    assert res.rms_after_mm < 2.0 and res.rms_before_mm > 3.0 * res.rms_after_mm


def test_depth_without_usable_pixels_is_refused():
    with pytest.raises(InvalidInputError, match="no board views"):
        fit_depth_errors([], [F_60_24_MHZ])
    v = DepthView("v", np.zeros((1, 10, 10)), np.ones((10, 10)), np.ones((10, 10)),
                  np.zeros((10, 10), bool))
    with pytest.raises(InvalidInputError, match="usable"):
        fit_depth_errors([v], [F_60_24_MHZ])


def _ringing_stack(gain, read, n=24, seed=0, shape=(60, 80), amplitude_px=0.3):
    """A smooth chequer whose image swings sideways over the stack, as a board on a table still
    ringing at 2.1 Hz (damping 0.18) under frames at 45 fps."""
    rng = np.random.default_rng(seed)
    cam = Camera(Intrinsics(shape[1], shape[0], 50.0, 50.0, 40.0, 30.0), np.eye(4))
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    sensor = SensorParams(adc_gain_e_per_dn=gain, read_noise_e=read)
    omega, zeta = 2 * np.pi * 2.1, 0.18
    frames = []
    for k in range(n):
        t = k / 45.0
        x = c + amplitude_px * np.exp(-zeta * omega * t) * np.sin(omega * t)
        chequer = np.sin(2 * np.pi * x / 20.0) * np.sin(2 * np.pi * r / 20.0)
        pattern = 0.5 + 0.5 * np.tanh(4.0 * chequer)  # squares with edges a pixel or two wide
        active = 200.0 + 60_000.0 * (x / shape[1]) * (0.3 + 0.7 * pattern)
        e = PixelElectrons(active=active, ambient=np.zeros(shape), dark=1.0,
                           phasor=(0.6 * active * np.exp(-1j * 2.0))[None])
        frames.append(expose(e, cam, sensor, rng))
    return frames


@pytest.mark.parametrize(("gain", "read"), [(8.0, 15.0), (14.6, 48.6), (33.0, 24.0)])
def test_a_stack_taken_while_the_table_rings_still_gives_the_gain(gain, read):
    """The rig sweep's reality 203 took its noise stack on a table still ringing: the board's
    edges swept across pixels and their variance was 2-11 times the noise's (gain 58 % off).
    The successive differences and the flat pixels keep the curve to the noise."""
    frames = _ringing_stack(gain, read, seed=int(gain))
    c = np.stack([f.phase_images[0].astype(np.float64) for f in frames])
    # the motion is there: on the steepest tenth of the pixels the plain sample variance is
    # well above the successive differences'
    grad = steepest_gradient(c.mean(axis=0))
    steep = grad > np.percentile(grad, 90)
    assert np.median(c.var(axis=0, ddof=1).mean(axis=0)[steep]) > 1.5 * np.median(
        successive_difference_variance(c).mean(axis=0)[steep])
    res = calibrate_noise([frames])
    assert res.adc_gain_e_per_dn == pytest.approx(gain, rel=0.05)
    assert res.read_noise_e == pytest.approx(read, rel=0.10)
    assert res.reduced_chi2 < 2.0


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 64), seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-6, 1e6))
def test_the_successive_difference_variance_is_the_noise_s_variance(n, seed, scale):
    x = np.random.default_rng(seed).normal(0.0, scale, (n, 4000))
    v = successive_difference_variance(x)
    assert np.all(np.isfinite(v)) and np.all(v >= 0.0)
    # unbiased: the mean over 4000 columns within 5 of its own standard errors
    dof = successive_difference_dof(n)
    assert abs(v.mean() / scale**2 - 1.0) < 5.0 * np.sqrt(2.0 / dof / 4000)
    if n == 2:  # one pair: the sample variance itself
        np.testing.assert_allclose(v, x.var(axis=0, ddof=1), rtol=1e-12)
        assert dof == 1.0
    # a constant offset and a slow drift leave it (nearly) unchanged
    drift = x + 1e3 * scale + scale * 0.01 * np.arange(n)[:, None]
    assert successive_difference_variance(drift).mean() == pytest.approx(v.mean(), rel=1e-2)
