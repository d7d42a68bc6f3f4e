"""Verdicts: an estimate's error bars are never smaller than its residual supports."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from calibration.verdicts import (
    CHI2_UNEXPLAINED,
    VERDICTS_FILE,
    Verdict,
    Verdicts,
    honest_std,
    judge,
    read_verdicts,
    write_verdicts,
)

EDGES = st.sampled_from([math.nan, math.inf])
STD = st.one_of(st.floats(min_value=0.0, max_value=1e6), EDGES)
CHI2 = st.one_of(st.floats(min_value=0.0, max_value=1e9), EDGES)


@given(std=STD, chi2=CHI2)
def test_an_honest_std_is_never_below_the_statistical_one_nor_below_the_residual(std, chi2):
    out = honest_std(std, chi2)
    if not (math.isfinite(std) and math.isfinite(chi2)):
        assert out == math.inf
        return
    assert out >= std
    assert out >= std * math.sqrt(chi2) * (1 - 1e-12)


@given(std=st.one_of(STD, st.lists(STD, min_size=1, max_size=6)), chi2=CHI2,
       limit=st.floats(min_value=1e-9, max_value=1e3))
def test_no_fit_that_fails_to_explain_its_data_is_reported_determined(std, chi2, limit):
    v = judge(std, limit, reduced_chi2=chi2)
    if not math.isfinite(chi2) or chi2 > CHI2_UNEXPLAINED:
        assert v.verdict == "unexplained" and "chi-square" in v.reason
    elif v.determined:
        stds = v.std if isinstance(v.std, list) else [v.std]
        assert all(math.isfinite(s) and s <= limit for s in stds)
    json.dumps(v.to_json(), allow_nan=False)  # strict JSON whatever the input


def test_a_fit_that_explains_its_data_is_determined_with_its_own_error():
    v = judge(0.2, 1.0, reduced_chi2=0.8, unit=" mm")
    assert v == Verdict("determined", 0.2)
    v = judge([0.2, 0.4], 1.0, reduced_chi2=1.44)
    assert v.determined and v.std == pytest.approx([0.24, 0.48])


def test_a_wide_error_is_not_determined_and_says_by_how_much():
    v = judge(3.0, 1.0, reduced_chi2=1.0, unit=" mm")
    assert v.verdict == "not determined" and "3 mm above the limit 1 mm" in v.reason


def test_the_issue_s_case_is_unexplained_with_its_error_scaled_and_named():
    # fit-object on a side-on view: chi2 20.5, statistical std 0.06 mm, truly 3.1 mm off
    v = judge(0.06, 2.0, reduced_chi2=20.5, unit=" mm", where="views +90")
    assert v.verdict == "unexplained" and "views +90" in v.reason and "20.5" in v.reason
    assert v.std == pytest.approx(0.06 * math.sqrt(20.5))


def test_a_verdict_other_than_determined_needs_its_reason_and_the_names_are_fixed():
    with pytest.raises(ValueError, match="reason"):
        Verdict("not determined", None, None)
    with pytest.raises(ValueError, match="allowed: determined, not determined, unexplained"):
        Verdict("probably", 1.0)  # type: ignore[arg-type]


def test_verdicts_are_written_whole_as_a_flat_mapping_and_read_back(tmp_path):
    verdicts = Verdicts()
    verdicts.add("camera.fx_px", judge(0.3, 2.0))
    verdicts.update_from({"zero_offset_deg": judge(float("inf"), 0.1)}, prefix="turntable.")
    with pytest.raises(ValueError, match="judged twice"):
        verdicts.add("camera.fx_px", judge(0.3, 2.0))
    path = write_verdicts(tmp_path / VERDICTS_FILE, verdicts)
    data = json.loads(path.read_text())
    assert data == {
        "camera.fx_px": {"verdict": "determined", "std": 0.3, "reason": None},
        "turntable.zero_offset_deg": {"verdict": "not determined", "std": None,
                                      "reason": "its error is unbounded: the data do not pin "
                                                "it down (the limit is 0.1)"},
    }
    assert dict(read_verdicts(path)) == dict(verdicts)
    assert verdicts.counts() == {"determined": 1, "not determined": 1, "unexplained": 0}


@given(std=STD, spread=STD, chi2=st.floats(min_value=0.0, max_value=CHI2_UNEXPLAINED))
def test_the_spread_over_views_is_a_floor_under_the_reported_error(std, spread, chi2):
    v = judge(std, 1.0, reduced_chi2=chi2, spread=spread)
    if v.std is not None:
        assert v.std >= honest_std(std, chi2) or math.isnan(std)
        assert v.std >= spread or math.isnan(spread)
    if v.determined:  # a spread beyond the limit (or NaN) is never determined
        assert math.isfinite(spread) and spread <= 1.0


def test_a_spread_of_another_shape_is_a_bug():
    with pytest.raises(ValueError, match="2 values for 3"):
        judge([0.1, 0.1, 0.1], 1.0, spread=[0.1, 0.1])
