"""The PMD pixel model against closed forms: shot noise, SBI, ambient light.

Nominal inputs only; the numerical hard cases of the same model (Poisson draws up to 1e12
electrons, any non-negative input, signal beyond the SBI range, the whole chain at 100 suns,
1 mm and 10 km) are the separate suite tests/hard_cases/test_sensor_*.py.
"""

import dataclasses

import numpy as np
import pytest

from sim_core import frame_io
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.raw import reconstruct_raw
from sim_core.sensor import (
    PixelElectrons,
    SensorParams,
    expose,
    predicted_range_std_m,
    tap_means,
)
from tests.hard_cases.test_sensor_properties import RANGES_M, bright_electrons
from tests.sim_core.scenes import fronto_parallel_wall

F = 60.24e6
RANGE_M = 1.3


def electrons(active: float, ambient: float = 0.0, shape=(8, 8), range_m=RANGE_M):
    phase = 4 * np.pi * F * range_m / SPEED_OF_LIGHT_M_S
    ph = np.full(shape, active * np.exp(-1j * phase))[None]
    return PixelElectrons(np.full(shape, active), np.full(shape, ambient), 1.0, ph)


@pytest.fixture(scope="module")
def camera():
    return fronto_parallel_wall().camera


def repeat(e, camera, sensor, n, seed=0):
    rng = np.random.default_rng(seed)
    return [expose(e, camera, sensor, rng) for _ in range(n)]


def test_noise_free_taps_follow_peer_eqs_13_14(camera):
    s = SensorParams()
    a, b = tap_means(electrons(1000.0, 200.0), s)
    np.testing.assert_allclose(a + b, 1201.0)
    phi = 4 * np.pi * F * RANGE_M / SPEED_OF_LIGHT_M_S
    taus = np.array([0, 0.5, 1, 1.5]) * np.pi
    np.testing.assert_allclose((a - b)[0, :, 0, 0], 0.8 * 1000 * np.cos(taus + phi), rtol=1e-12)


def test_noise_free_frame_reconstructs_the_exact_range(camera):
    s = SensorParams(read_noise_e=0.0)
    raw = expose(electrons(5000.0), camera, s, None)
    img = reconstruct_raw(raw, np.ones((8, 8)))
    np.testing.assert_allclose(img.range_m, RANGE_M, atol=1e-9)




@pytest.mark.parametrize("active_e", [60.0, 250.0, 1000.0])
def test_the_noise_free_frame_is_the_noisy_frames_mean_for_dim_pixels_too(active_e, camera):
    # 48 e- of read noise: the dim taps go below 0 often, where the readout clips them
    s = SensorParams(read_noise_e=48.0)
    e = electrons(active_e, shape=(16, 16))
    clean = expose(e, camera, s, None)
    frames = repeat(e, camera, s, 400, seed=3)
    mean = np.mean([f.phase_images.astype(np.float64) for f in frames], axis=0)
    mean_taps = np.mean([f.taps.astype(np.float64) for f in frames], axis=0)
    # the standard error of a mean over 400 frames x 256 pixels, a few times over
    tap_sem = np.std([f.taps for f in frames]) / np.sqrt(400 * 256)
    np.testing.assert_allclose(mean_taps.mean(axis=(-2, -1)), clean.taps.mean(axis=(-2, -1)),
                               atol=5 * tap_sem + 0.02)
    np.testing.assert_allclose(mean.mean(axis=(-2, -1)), clean.phase_images.mean(axis=(-2, -1)),
                               atol=7 * tap_sem + 0.02)
    # the clipping takes a dim pixel's amplitude down: the charges' own A - B is larger
    unclipped = expose(e, camera, SensorParams(read_noise_e=0.0), None)
    if active_e < 500.0:
        assert np.abs(clean.phasor()).mean() < np.abs(unclipped.phasor()).mean()


# (from tests/hard_cases: the same behaviour as the test above, over a range sweep and with
# the SBI compensation active at 4e4 e-)
@pytest.mark.parametrize("active_e", [1e4, 4e4])
def test_modulated_signal_within_the_sbi_range_reconstructs_exactly(active_e, camera):
    raw = expose(bright_electrons(active_e), camera, SensorParams(read_noise_e=0.0), None)
    img = reconstruct_raw(raw, np.ones(RANGES_M.shape))
    assert img.valid.all()
    np.testing.assert_allclose(img.range_m, RANGES_M, atol=1e-6)


def test_range_noise_follows_the_shot_noise_prediction(camera):
    s = SensorParams(read_noise_e=10.0, adc_gain_e_per_dn=1.0, adc_bits=24, full_well_e=1e6)
    e = electrons(3000.0, 2000.0, shape=(16, 16))
    frames = repeat(e, camera, s, 150)
    ranges = np.stack([reconstruct_raw(r, np.ones((16, 16))).range_m for r in frames])
    measured = ranges.std(axis=0, ddof=1).mean()
    predicted = predicted_range_std_m(e, s, F).mean()
    # 150 frames x 256 pixels: the standard error of the pooled std is about 0.3 %; the
    # prediction neglects quantisation (1 e-/DN here), so allow 5 %.
    assert measured == pytest.approx(predicted, rel=0.05)
    assert abs(ranges.mean() - RANGE_M) < 3 * predicted / np.sqrt(ranges.size)


def test_sbi_keeps_the_mean_difference_and_adds_variance(camera):
    s = SensorParams(read_noise_e=0.0, adc_gain_e_per_dn=1.0, adc_bits=24, full_well_e=1e7,
                     sbi_limit_e=1e9)
    dark = electrons(2000.0, 0.0, shape=(16, 16))
    bright = electrons(2000.0, 300_000.0, shape=(16, 16))  # far beyond n_SBI,start
    c_dark = np.stack([r.phase_images for r in repeat(dark, camera, s, 60)])
    c_bright = np.stack([r.phase_images for r in repeat(bright, camera, s, 60, seed=1)])
    frame = repeat(bright, camera, s, 1)[0]
    assert frame.taps.max() <= s.sbi_start_e + 2000.0  # compensation kept the taps in range
    mean_err = np.abs(c_bright.mean(axis=0) - c_dark.mean(axis=0)).mean()
    assert mean_err < 4 * np.sqrt(c_bright.var(axis=0).mean() / 60)
    assert c_bright.var(axis=0).mean() > 10 * c_dark.var(axis=0).mean()


def test_more_ambient_light_raises_depth_noise(camera):
    s = SensorParams(adc_gain_e_per_dn=1.0, adc_bits=24, full_well_e=1e7, sbi_limit_e=1e9)
    stds = []
    for ambient in (0.0, 20_000.0, 200_000.0):
        frames = repeat(electrons(3000.0, ambient, shape=(16, 16)), camera, s, 40)
        r = np.stack([reconstruct_raw(f, np.ones((16, 16))).range_m for f in frames])
        stds.append(r.std(axis=0).mean())
    assert stds[0] < stds[1] < stds[2]


def test_zero_signal_is_invalid_and_finite(camera):
    raw = expose(electrons(0.0, 0.0), camera, SensorParams(), np.random.default_rng(0))
    img = reconstruct_raw(raw, np.ones((8, 8)))
    assert not img.valid.any()
    assert np.isnan(img.range_m).all()
    assert np.isfinite(img.amplitude).all() and np.isfinite(img.intensity).all()


def test_full_saturation_without_sbi_is_flagged_invalid(camera):
    s = SensorParams(sbi_enabled=False)
    raw = expose(electrons(1e7, 1e7), camera, s, np.random.default_rng(0))
    img = reconstruct_raw(raw, np.ones((8, 8)))
    assert raw.saturated.all() and not img.valid.any()
    assert np.isfinite(raw.phase_images).all()


def test_ambient_beyond_the_sbi_limit_invalidates_the_pixel(camera):
    s = SensorParams()
    raw = expose(electrons(3000.0, 1e12), camera, s, np.random.default_rng(0))
    assert raw.sbi_limit.all()
    assert not reconstruct_raw(raw, np.ones((8, 8))).valid.any()


def test_raw_frame_round_trips_through_npz(tmp_path, camera):
    raw = expose(electrons(3000.0, 100.0), camera, SensorParams(), np.random.default_rng(2))
    frame_io.write_raw(tmp_path / "raw.npz", raw)
    back = frame_io.read_raw(tmp_path / "raw.npz")
    for f in ("phase_images", "intensity", "frequencies_hz", "saturated", "sbi_limit", "taps"):
        np.testing.assert_array_equal(getattr(back, f), getattr(raw, f))
    assert back.meta["sensor"] == dataclasses.asdict(SensorParams())


@pytest.mark.parametrize(("field", "value"), [("fill_factor", 0.0), ("adc_bits", 40),
                                               ("quantum_efficiency", float("nan"))])
def test_bad_sensor_parameter_names_the_field(field, value):
    with pytest.raises(ValueError, match=f"sensor.{field}"):
        SensorParams(**{field: value})
