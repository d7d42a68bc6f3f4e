"""The one angle-list grammar (:func:`calibration.angles.parse_angles`) and the sweep rule
(:func:`calibration.angles.sweep_angles`): the range form is the explicit list, every limit is
the caller's, and bad input is an error naming the caller's field and the allowed range."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.angles import (
    MAX_ANGLES,
    SWEEP_COUNT_RANGE,
    SWEEP_STEP_RANGE_DEG,
    AngleLimits,
    angle_range,
    parse_angles,
    sweep_angles,
)
from sim_core.errors import InvalidInputError

#: angles on a quarter-degree grid (exact in binary: the range and the list agree to the bit)
quarters = st.integers(-1440, 1440).map(lambda k: k / 4)


@settings(max_examples=200, deadline=None)
@given(start=quarters, step=st.integers(1, 360).map(lambda k: k / 4), n=st.integers(1, 60),
       beyond=st.sampled_from([0.0, 0.25, 0.5, 0.999]))
def test_the_range_form_is_the_explicit_list(start, step, n, beyond):
    stop = start + (n - 1 + beyond) * step  # the end is included only when a step reaches it
    expected = tuple(start + i * step for i in range(n))
    wide = AngleLimits(lo_deg=-1e6, hi_deg=1e6)
    got = parse_angles(f"{start!r}:{stop!r}:{step!r}", field="f", limits=wide)
    assert got == expected
    assert parse_angles(", ".join(repr(a) for a in expected), field="f", limits=wide) == expected
    assert parse_angles(" ".join(repr(a) for a in expected), field="f",
                        limits=wide) == expected  # spaces separate as commas do (the page's)


@settings(max_examples=200, deadline=None)
@given(start=st.floats(-400, 400), span=st.floats(0, 800), step=st.floats(0.01, 200))
def test_a_range_ends_within_a_step_of_its_end_and_never_beyond(start, span, step):
    stop = start + span
    try:
        got = angle_range(start, stop, step, field="f")
    except InvalidInputError as exc:  # only ever: too many angles
        assert exc.field == "f" and f"at most {MAX_ANGLES}" in exc.message
        assert span / step + 1 > MAX_ANGLES - 1
        return
    assert got[0] == pytest.approx(start, abs=1e-9)
    assert got[-1] <= stop and stop - got[-1] < step * (1 + 1e-9)
    assert all(b - a == pytest.approx(step, abs=2e-9) for a, b in itertools.pairwise(got))


@settings(max_examples=300, deadline=None)
@given(text=st.text(alphabet="0123456789.,:-+eE xin \t", max_size=30)
       | st.text(max_size=30))
def test_any_text_gives_angles_within_the_limits_or_an_error_naming_the_field(text):
    try:
        got = parse_angles(text, field="--angles", limits=AngleLimits(
            lo_deg=-90.0, hi_deg=90.0, max_count=12, distinct=True))
    except InvalidInputError as exc:
        assert exc.field == "--angles"
        assert "allowed" in exc.message or "give FROM:TO:STEP" in exc.message, exc.message
        return
    assert 1 <= len(got) <= 12 and len(set(got)) == len(got)
    assert all(math.isfinite(a) and -90.0 <= a <= 90.0 for a in got)


@pytest.mark.parametrize(("text", "kwargs", "words"), [
    ("", {}, "0 angle(s); allowed: 1 to"),
    ("0,x", {}, "'x' is not a number"),
    ("nan", {}, "'nan' is not a number"),
    ("1e400", {}, "inf deg is outside the allowed [-360, 360]"),
    ("0:10", {}, "2 parts"),
    ("0:10:0", {}, "STEP is 0 deg; allowed: above 0"),
    ("10:-10:5", {}, "TO (-10) is below FROM (10)"),
    ("0:1e300:1e-300", {}, "allowed: at most 721"),
    ("0:100:1", {"max_count": 36}, "101 angles; allowed: at most 36"),
    ("0,88", {"lo_deg": -85, "hi_deg": 85, "why_range": "edge-on"},
     "88.0 deg is outside the allowed [-85, 85] deg (edge-on)"),
    ("0, 30, 0", {"distinct": True}, "0 deg is given twice"),
    ("0", {"min_count": 3}, "1 angle(s); allowed: 3 to"),
])
def test_bad_text_names_the_field_and_what_is_allowed(text, kwargs, words):
    with pytest.raises(InvalidInputError) as exc:
        parse_angles(text, field="--angles", limits=AngleLimits(**kwargs))
    assert exc.value.field == "--angles"
    assert words in exc.value.message, exc.value.message


def test_the_forms_the_docs_show():
    assert parse_angles("-10:10:5", field="f") == (-10.0, -5.0, 0.0, 5.0, 10.0)
    assert parse_angles("0:10:4", field="f") == (0.0, 4.0, 8.0)  # 10 is not reached
    assert parse_angles("0:1:0.1", field="f")[3] == 0.3  # rounded to 1e-9 deg
    assert parse_angles(" -30, -10 10,30 ", field="f") == (-30.0, -10.0, 10.0, 30.0)
    assert parse_angles("0, 30, 0", field="f") == (0.0, 30.0, 0.0)  # twice unless distinct
    assert parse_angles("-0", field="f") == (-0.0,)


@settings(max_examples=200, deadline=None)
@given(start=st.floats(-360, 360), to=st.floats(-360, 360),
       step=st.floats(*SWEEP_STEP_RANGE_DEG))
def test_the_sweep_is_the_grammars_range_within_its_limits(start, to, step):
    try:
        got = sweep_angles(start, to, step)
    except InvalidInputError as exc:
        assert exc.field in ("sweep", "sweep.step_deg")
        assert "allowed" in exc.message or "must be greater" in exc.message
        n = math.floor((to - start) / step + 1e-9) + 1
        assert not (to > start and SWEEP_COUNT_RANGE[0] <= n <= SWEEP_COUNT_RANGE[1])
        return
    assert SWEEP_COUNT_RANGE[0] <= len(got) <= SWEEP_COUNT_RANGE[1]
    assert got == parse_angles(f"{start!r}:{to!r}:{step!r}", field="f")


@pytest.mark.parametrize(("args", "field"), [
    ((-55.0, 55.0, 60.0), "sweep"),  # two angles: the axis needs three
    ((10.0, -10.0, 5.0), "sweep"),
    ((-360.0, 360.0, 0.5), "sweep.step_deg"),  # 1441 angles
    ((-55.0, 55.0, 0.1), "sweep.step_deg"),  # below the step's range
    ((-400.0, 55.0, 5.0), "sweep.from_deg"),
    ((-55.0, math.inf, 5.0), "sweep.to_deg"),
])
def test_a_bad_sweep_names_its_input(args, field):
    with pytest.raises(InvalidInputError) as exc:
        sweep_angles(*args)
    assert exc.value.field == field
    assert "allowed" in exc.value.message or "must be greater" in exc.value.message


def test_the_default_sweep_is_the_documented_one():
    assert sweep_angles() == tuple(float(a) for a in range(-55, 56, 5))
    assert sweep_angles(-55, 55, 45) == (-55.0, -10.0, 35.0)
