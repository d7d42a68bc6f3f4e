"""The settling measured from the table's angle after a move: frequency, damping, amplitude."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.settling import fit_settling, plane_yaw_deg
from sim_core.errors import InvalidInputError
from sim_core.settling import ringing_deg
from sim_core.twin_file import TurntableSettling

KEYS = ("turntable.settling.amplitude_deg", "turntable.settling.frequency_hz",
        "turntable.settling.damping_ratio")


def _series(truth: TurntableSettling, noise_deg: float, seed: int = 0, fps: float = 45.0,
            duration_s: float = 3.0, t_end_s: float = 0.05, rest_deg: float = 30.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / fps)
    y = rest_deg + ringing_deg(truth, t - t_end_s) + noise_deg * rng.standard_normal(t.size)
    return t, y


@pytest.mark.parametrize("seed", range(5))
def test_a_clear_ringing_is_measured_within_its_targets(seed):
    truth = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.5, damping_ratio=0.06)
    t, y = _series(truth, 0.005, seed)
    fit = fit_settling(t, y, 0.005)
    assert all(fit.verdicts[k].determined for k in KEYS)
    s = fit.settling
    assert s.frequency_hz == pytest.approx(2.5, rel=0.05)  # the target
    assert s.damping_ratio == pytest.approx(0.06, rel=0.3)
    assert s.amplitude_deg == pytest.approx(0.2, rel=0.2)
    assert fit.t0_s == pytest.approx(0.05, abs=0.02)
    assert fit.offset_deg == pytest.approx(30.0, abs=0.005)
    # the std it claims covers its error
    f_std = fit.verdicts["turntable.settling.frequency_hz"].std
    assert abs(s.frequency_hz - 2.5) < 4 * f_std
    assert 0.5 < fit.reduced_chi2 < 1.6


def test_a_ringing_below_the_noise_is_not_determined():
    truth = TurntableSettling(amplitude_deg=0.002, frequency_hz=2.5, damping_ratio=0.3)
    t, y = _series(truth, 0.05, 1)
    fit = fit_settling(t, y, 0.05)
    assert fit.settling is None
    assert not all(fit.verdicts[k].determined for k in KEYS)
    assert all(fit.verdicts[k].reason for k in KEYS if not fit.verdicts[k].determined)


@pytest.mark.parametrize("seed", range(6))
def test_a_table_that_does_not_ring_determines_no_frequency(seed):
    """Noise alone: the fit still finds some frequency, but no key of a ringing that is not
    there is determined (the rig's round trips once got "determined" frequencies from a table
    that had settled at once)."""
    t = np.arange(90) / 11.0
    y = 20.0 + np.random.default_rng(seed).normal(0.0, 0.04, t.size)
    fit = fit_settling(t, y, 0.04)
    assert fit.settling is None
    for k in KEYS:
        assert fit.verdicts[k].verdict == "not determined", fit.verdicts[k]
        assert "no ringing above the yaw's noise" in fit.verdicts[k].reason


def test_a_series_the_model_does_not_explain_is_unexplained():
    truth = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.5, damping_ratio=0.06)
    t, y = _series(truth, 0.005, 2)
    y = y + 0.1 * np.sin(2 * np.pi * 7.3 * t)  # a second mode the model has not
    fit = fit_settling(t, y, 0.005)
    assert fit.settling is None
    assert any(fit.verdicts[k].verdict == "unexplained" for k in KEYS)
    assert "reduced chi-square" in fit.verdicts[KEYS[1]].reason


def test_frames_too_slow_for_the_ringing_are_refused_as_not_determined():
    truth = TurntableSettling(amplitude_deg=0.2, frequency_hz=2.5, damping_ratio=0.02)
    t, y = _series(truth, 0.005, 3, fps=6.0, duration_s=20.0)
    fit = fit_settling(t, y, 0.005)
    assert fit.settling is None
    assert all(fit.verdicts[k].verdict == "not determined" for k in KEYS)


@pytest.mark.parametrize(("t", "y", "std", "field"), [
    (np.arange(5.0), np.zeros(5), 0.01, "t_s"),
    (np.arange(20.0), np.zeros(19), 0.01, "t_s"),
    (np.arange(20.0)[::-1], np.zeros(20), 0.01, "t_s"),
    (np.arange(20.0), np.r_[np.zeros(19), np.nan], 0.01, "angle_deg"),
    (np.arange(20.0), np.zeros(20), 0.0, "angle_std_deg"),
])
def test_bad_series_are_refused_naming_the_field(t, y, std, field):
    with pytest.raises(InvalidInputError) as err:
        fit_settling(t, y, std)
    assert err.value.field == field


@settings(max_examples=8, deadline=None)
@given(st.floats(0.05, 1.0), st.floats(1.0, 6.0), st.floats(0.02, 0.2), st.integers(0, 99))
def test_the_fit_never_returns_a_confident_wrong_frequency(amp, f, zeta, seed):
    truth = TurntableSettling(amplitude_deg=amp, frequency_hz=f, damping_ratio=zeta)
    t, y = _series(truth, 0.01, seed)
    fit = fit_settling(t, y, 0.01)
    v = fit.verdicts["turntable.settling.frequency_hz"]
    assert np.isfinite(fit.reduced_chi2)
    if fit.settling is not None:
        assert fit.settling.frequency_hz == pytest.approx(f, rel=0.05)
    if v.determined:
        assert v.std is not None and v.std > 0


def test_the_yaw_of_a_turned_board_is_its_angle():
    x, y = np.meshgrid(np.linspace(-0.1, 0.1, 5), np.linspace(-0.1, 0.1, 5))
    board = np.stack([x.ravel(), y.ravel(), np.zeros(25)], axis=1)
    for yaw in (-20.0, 0.0, 7.5):
        a = np.radians(yaw)
        rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        pts = board @ rot.T + [0.0, 0.0, 1.0]
        assert plane_yaw_deg(pts) == pytest.approx(-yaw, abs=1e-9) or plane_yaw_deg(
            pts) == pytest.approx(yaw, abs=1e-9)
    with pytest.raises(InvalidInputError, match="collinear"):
        plane_yaw_deg(np.array([[0, 0, 1.0], [1, 0, 1.0], [2, 0, 1.0]]))
