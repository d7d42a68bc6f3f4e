"""Effective source power and solar scale: recovered from synthetic frames; refusals are clear."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.photometry import fit_source_power, white_square_mask
from calibration.solar import fit_solar_scale
from sim_core.errors import InvalidInputError


def _board(shape=(60, 80), square=10):
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]]
    white = ((r // square + c // square) % 2) == 0
    falloff = 1.0 - 0.3 * ((c - 40) ** 2 + (r - 30) ** 2) / 2500.0
    return np.where(white, 0.85, 0.04) * falloff * 800.0


@pytest.mark.parametrize("true_ratio", [0.6, 1.0, 1.35, 2.2])
def test_power_is_the_amplitude_ratio_on_white_squares(true_ratio):
    rng = np.random.default_rng(1)
    pred = _board()
    meas = pred * true_ratio + rng.normal(0.0, 3.0, pred.shape)
    res = fit_source_power(meas, pred, nominal_power_w=1.0)
    assert res.power_w == pytest.approx(true_ratio, rel=0.01)
    assert res.n_pixels > 500 and res.ratio_std_error < 0.005
    # Square edges are never used: a 1 px shift of the measured image changes little.
    shifted = np.roll(meas, 1, axis=1)
    assert fit_source_power(shifted, pred, 1.0).power_w == pytest.approx(true_ratio, rel=0.02)


def test_power_needs_a_board_in_view():
    with pytest.raises(InvalidInputError, match="white squares"):
        fit_source_power(np.zeros((20, 20)), np.zeros((20, 20)), 1.0)
    with pytest.raises(InvalidInputError, match="nominal_power_w"):
        fit_source_power(_board(), _board(), 0.0)
    assert not white_square_mask(np.full((5, 5), np.nan)).any()


def _predictor(active, response, sbi_dn=None):
    def predict(true_suns):
        i = active + response * true_suns
        return np.minimum(i, sbi_dn) if sbi_dn is not None else i
    return predict


@pytest.mark.parametrize("scale", [0.9, 1.06, 1.2])
def test_solar_scale_from_the_intensity_response(scale):
    rng = np.random.default_rng(2)
    active = _board() * 0.5
    response = np.full(active.shape, 300.0)
    predict = _predictor(active, response)
    levels = [0.0, 0.8, 1.0, 1.2]
    std = [np.full(active.shape, 2.0)] * 4
    meas = [predict(s * scale) + rng.normal(0, 2.0, active.shape) for s in levels]
    res = fit_solar_scale(levels, meas, std, predict)
    assert res.method == "frames"
    assert res.irradiance_scale == pytest.approx(scale, rel=0.005)


def test_a_response_flattened_by_sbi_needs_a_reference_cell():
    active = _board() * 0.5
    response = np.full(active.shape, 300.0)
    predict = _predictor(active, response, sbi_dn=1.0)  # everything clipped: no response
    levels = [0.0, 1.0, 1.2]
    meas = [predict(s) for s in levels]
    std = [np.full(active.shape, 2.0)] * 3
    with pytest.raises(InvalidInputError, match="reference cell"):
        fit_solar_scale(levels, meas, std, predict)
    res = fit_solar_scale(levels, meas, std, predict, reference_cell_suns=1.04)
    assert res.method == "reference-cell" and res.irradiance_scale == 1.04
    with pytest.raises(InvalidInputError, match="at least two"):
        fit_solar_scale([1.0], meas[:1], std[:1], predict)
