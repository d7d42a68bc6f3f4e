"""The explained difference carries the depth difference and pixel shares of each comparison:
against the nominal twin, the fitted twin and a second capture of the same state (the noise
ceiling)."""

from __future__ import annotations

import numpy as np
import pytest

from service.lab.comparison import compare, explained_difference
from service.lab.requests import MaskSpec
from sim_core.tof import ToFImage

H, W = 30, 40


def frame(range_m: np.ndarray, amplitude: float = 100.0) -> ToFImage:
    valid = np.isfinite(range_m)
    return ToFImage(range_m=range_m, depth_z_m=range_m, amplitude=np.full((H, W), amplitude),
                    intensity=np.full((H, W), 2 * amplitude), phase_rad=np.zeros((1, H, W)),
                    valid=valid, frequencies_hz=np.array([80.32e6]))


def test_the_noise_ceiling_reports_the_same_figures_for_two_captures():
    gen = np.random.default_rng(1)
    truth = np.full((H, W), 1.2)
    truth[:, 25:] = 2.0  # an edge: the measured frame has a mixed column there
    measured = truth + gen.normal(0.0, 0.002, (H, W))
    measured[:, 25] = 1.6
    second = truth + gen.normal(0.0, 0.002, (H, W))  # the same state, captured again
    second[:, 25] = 1.6
    nominal_sim = truth + 0.030  # the nominal twin 30 mm too far, a clean edge
    fitted_sim = truth + 0.004  # the fitted twin 4 mm too far
    nominal = compare(frame(measured), frame(nominal_sim), None, (2048.0, 2048.0))
    out = explained_difference(
        MaskSpec(kind="all"), frame(measured), frame(second), 2048.0, nominal,
        frame(fitted_sim), None, 2048.0, [], [])
    assert "error" not in out, out
    medians = {t: out[t]["tof"]["depth_diff_median_mm"] for t in ("nominal", "fitted", "ceiling")}
    assert medians["nominal"] == pytest.approx(30.0, abs=1.0)
    assert medians["fitted"] == pytest.approx(4.0, abs=1.0)
    assert medians["ceiling"] == pytest.approx(0.0, abs=1.0)
    # two captures of the noise sigma = 2 mm differ by sqrt(2) sigma: MAD = 0.674 * 2.83 mm
    assert out["ceiling"]["tof"]["depth_diff_mad_mm"] == pytest.approx(1.9, abs=0.4)
    # the mixed column is flying in both captures, in neither simulation
    assert out["ceiling"]["tof"]["flying_share_measured"] == pytest.approx(1 / W)
    assert out["ceiling"]["tof"]["flying_share_simulated"] == pytest.approx(1 / W)
    assert out["fitted"]["tof"]["flying_share_simulated"] == 0.0
    assert out["ceiling"]["tof"]["depth_diff_n_pixels"] == H * (W - 1)


def test_a_fitted_twin_beyond_the_ceiling_names_the_residual_and_where_it_is():
    gen = np.random.default_rng(2)
    truth = np.full((H, W), 1.2)
    measured, second, twin = (truth + gen.normal(0.0, 0.002, (H, W)) for _ in range(3))
    ex = lambda fitted: explained_difference(  # noqa: E731
        MaskSpec(kind="all"), frame(measured), frame(second), 2048.0, None, frame(fitted),
        None, 2048.0, [], [])
    # a twin as good as a second capture: within the ceiling, nothing unexplained
    assert ex(twin)["unexplained"] == []
    # 5 mm too far everywhere (a warm-up drift the twin does not model)
    out = ex(twin + 0.005)["unexplained"]
    assert [u["channel"] for u in out] == ["depth"], out
    top = out[0]["where"]["components"][0]
    assert top["shape"] == "offset" and top["mean"] == pytest.approx(-5.0, abs=0.3)
    assert out[0]["text"].startswith("depth RMSE 5.")
    assert "a common offset of -5" in out[0]["text"] and "the compared pixels" in out[0]["text"]


def test_a_twin_too_dark_is_beyond_the_grey_ceiling():
    gen = np.random.default_rng(3)
    truth = np.full((H, W), 1.2)
    measured, second = (truth + gen.normal(0.0, 0.002, (H, W)) for _ in range(2))
    amplitude = lambda a: gen.normal(a, 40.0, (H, W))  # noqa: E731
    m, s, f = (frame(r) for r in (measured, second, measured))
    m.amplitude[:], s.amplitude[:], f.amplitude[:] = amplitude(1000), amplitude(1000), amplitude(
        800)
    out = explained_difference(MaskSpec(kind="all"), m, s, 2048.0, None, f, None, 2048.0, [], [])
    grey = [u for u in out["unexplained"] if u["channel"] == "grey"]
    assert grey and "dB below" in grey[0]["by"], out["unexplained"]
    top = grey[0]["where"]["components"][0]
    assert top["shape"] == "offset" and top["mean"] > 20.0  # the twin is 25 grey levels darker
