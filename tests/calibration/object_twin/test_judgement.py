"""The object fit's verdicts on constructed fits: what each kind of evidence makes of a key."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.object_twin.judgement import (
    ONE_VIEW,
    POSITION_KEY,
    ROTATION_KEY,
    after_dropped_views,
    estimates,
    object_verdicts,
    scale_key,
    unfit_views,
)
from calibration.object_twin.refine import RefinedFit
from calibration.object_twin.reflectance import ObjectPixels
from sim_core.scene_spec import ObjectPose

ANGLES = [-60.0, 0.0, 85.0]
PIXELS = {"body": ObjectPixels("body", (), 900, 80.0, True),
          "pedestal": ObjectPixels("pedestal", (), 3, 12.0, False, "not seen enough")}


def _fit(chi2: float = 1.0, per_view=(1.0, 1.0, 1.0), jk_pos=(1e-4, 1e-4, 1e-4),
         jk_scale: float = 0.01) -> RefinedFit:
    return RefinedFit(
        offset=ObjectPose(), scales={"body": 1.05}, std_position_m=(2e-5, 2e-5, 2e-5),
        std_rotation_deg=(0.01, 0.01, 0.01), std_scale={"body": 0.002},
        determined={}, chi2_before=5.0, chi2_after=chi2, n_residuals=10_000, evaluations=40,
        chi2_per_view=tuple(per_view), jackknife_position_m=tuple(jk_pos),
        jackknife_rotation_deg=(0.02, 0.02, 0.02), jackknife_scale={"body": jk_scale})


def test_a_fit_that_explains_its_data_claims_the_larger_of_its_error_and_the_views_spread():
    v = object_verdicts(_fit(), PIXELS, ANGLES)
    assert list(v) == [POSITION_KEY, ROTATION_KEY, scale_key("body"), scale_key("pedestal")]
    assert v[POSITION_KEY].determined and v[POSITION_KEY].std == pytest.approx([1e-4] * 3)
    assert v[scale_key("body")].std == pytest.approx(0.01)
    assert v[scale_key("pedestal")].verdict == "not determined"
    assert v[scale_key("pedestal")].reason == "not seen enough"


def test_a_fit_that_does_not_explain_its_data_names_the_views_that_do_not_fit():
    v = object_verdicts(_fit(chi2=20.5, per_view=(1.1, 1.3, 58.0)), PIXELS, ANGLES)
    for key in (POSITION_KEY, ROTATION_KEY, scale_key("body")):
        assert v[key].verdict == "unexplained"
        assert "views +85 deg (chi-square 58)" in v[key].reason and "20.5" in v[key].reason
    assert v[POSITION_KEY].std[0] >= 2e-5 * math.sqrt(20.5)


def test_one_view_the_model_does_not_explain_leaves_every_key_unexplained_whatever_the_rest():
    # three views explained pull the chi-square of all four below the limit: the fourth is
    # still a view the model does not explain
    v = object_verdicts(_fit(chi2=1.6, per_view=(1.0, 1.1, 0.9, 3.4)), PIXELS, [*ANGLES, 60.0])
    for key in (POSITION_KEY, ROTATION_KEY, scale_key("body")):
        assert v[key].verdict == "unexplained"
        assert "views +60 deg (chi-square 3.4)" in v[key].reason
    # every view explained: the chi-square of all decides
    assert object_verdicts(_fit(chi2=1.6, per_view=(1.0, 1.1, 0.9, 1.9)), PIXELS,
                           [*ANGLES, 60.0])[POSITION_KEY].determined


def test_a_key_one_view_alone_determines_is_not_determined_and_says_why():
    v = object_verdicts(_fit(jk_scale=math.inf), PIXELS, ANGLES)
    assert v[scale_key("body")].verdict == "not determined"
    assert v[scale_key("body")].reason == ONE_VIEW
    assert v[POSITION_KEY].determined  # the others keep theirs


def test_a_spread_beyond_the_limit_is_not_determined():
    v = object_verdicts(_fit(jk_pos=(1e-4, 3e-3, 1e-4)), PIXELS, ANGLES)
    assert v[POSITION_KEY].verdict == "not determined"
    assert "above the limit" in v[POSITION_KEY].reason


@pytest.mark.parametrize(("chi2", "expected"), [
    ((1.0, 3.0, 2.5), [1, 2]), ((1.0, 1.0), []), ((np.nan, 3.0), [0, 1]), ((np.inf, 9.0), [0, 1]),
])
def test_the_views_that_do_not_fit_come_worst_first(chi2, expected):
    assert unfit_views(chi2) == expected


def test_after_views_are_left_out_no_key_is_determined():
    # Unmodelled stray light: the face-on view is left out (chi-square 7.3); the body's scale,
    # 3 % low in every view, hardly moves without it and its refit error is 0.2 %: a confident
    # wrong number unless marked. The pose moved; what was not determined stays so.
    refit = object_verdicts(_fit(jk_scale=0.001), PIXELS, ANGLES)
    with_dropped = estimates((0.001, 0.002, 0.0), (0.5, 0.0, 0.0), {"body": 0.970})
    without = estimates((0.0011, 0.002, 0.0), (0.5, 0.0, 0.0), {"body": 0.969})
    marked = after_dropped_views(refit, with_dropped, without, "views +0 deg")
    body = marked[scale_key("body")]
    assert body.verdict == "unexplained" and "views +0 deg" in body.reason
    assert "0.001, 0.5 standard deviations" in body.reason and body.std == refit[
        scale_key("body")].std
    assert marked[POSITION_KEY].verdict == "unexplained"
    assert marked[scale_key("pedestal")] == refit[scale_key("pedestal")]
