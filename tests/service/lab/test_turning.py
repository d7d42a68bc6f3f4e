"""Capture while turning: the campaign option's range, and the time a pose takes either way."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from service.lab.requests import TURNING_SPEED_RANGE_DEG_S, CampaignCreate
from service.lab.turning import _move_s, lead_deg, stop_and_go_s, turning_s
from sim_core.errors import InvalidInputError


def _campaign(**kw):
    return CampaignCreate(name="t", poses=[{"turntable_deg": 0.0}], **kw)


def test_a_campaign_turns_only_at_a_speed_the_stage_can_give():
    assert _campaign().turning_deg_s is None  # stop and go
    assert _campaign(turning_deg_s=10.0).turning_deg_s == 10.0
    for bad in (0.0, 0.05, 20.5, float("nan"), float("inf")):
        with pytest.raises(ValidationError) as err:
            _campaign(turning_deg_s=bad)
        assert err.value.errors()[0]["loc"] == ("turning_deg_s",)
        assert "allowed: 0.1 to 20 deg/s" in str(err.value)
    schema = CampaignCreate.model_json_schema()["properties"]["turning_deg_s"]["anyOf"][0]
    assert (schema["minimum"], schema["maximum"]) == TURNING_SPEED_RANGE_DEG_S


def test_the_move_time_is_the_trapezoid_of_the_smc100_simulator():
    from drivers.sim.smc100 import trapezoid

    for d in (0.1, 2.0, 5.0, 10.0, 45.0):
        segments = trapezoid(0.0, d, 20.0, 80.0)
        assert _move_s(d, 20.0, 80.0) == pytest.approx(segments[-1].t0 + segments[-1].duration)


def test_turning_beats_stop_and_go_when_the_table_must_settle():
    angles = [-20.0, -10.0, 0.0, 10.0, 20.0]
    go = stop_and_go_s(angles, 20.0, 80.0, settle_s=2.0, frame_s=1 / 45)
    turn = turning_s(angles, 10.0, 80.0, frame_s=1 / 45)
    assert turn < go
    assert turn == pytest.approx(lead_deg(10.0, 80.0) / 10.0 + 4.0 + 1 / 45)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 340.0), st.floats(0.1, 20.0), st.floats(1.0, 320.0))
def test_move_and_lead_times_are_finite_positive_and_continuous(d, v, a):
    t = _move_s(d, v, a)
    assert math.isfinite(t) and t >= 0.0
    assert t >= d / v - 1e-12  # never faster than the top speed
    # continuous where the triangle becomes a trapezoid (d = v^2 / a)
    edge = v * v / a
    assert _move_s(edge * (1 - 1e-9), v, a) == pytest.approx(_move_s(edge, v, a), rel=1e-6)
    assert math.isfinite(lead_deg(v, a)) and lead_deg(v, a) > 0.0


def test_a_stage_without_acceleration_is_refused():
    with pytest.raises(InvalidInputError, match="acceleration_deg_s2"):
        lead_deg(10.0, 0.0)
