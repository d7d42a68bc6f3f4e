"""The turntable's settling: its key in calibration and reality files, and the ringing's formula."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError
from sim_core.settling import damped_frequency_hz, envelope_deg, ringing_deg, settle_time_s
from sim_core.twin_file import (
    TurntableSettling,
    dump_yaml,
    parse_calibration,
    parse_reality,
    twin_hash,
)

SETTLING = {"amplitude_deg": 0.2, "frequency_hz": 2.5, "damping_ratio": 0.08}

settlings = st.builds(
    TurntableSettling,
    amplitude_deg=st.floats(0.0, 5.0),
    frequency_hz=st.floats(0.05, 500.0),
    damping_ratio=st.floats(0.001, 0.9),
)


@pytest.mark.parametrize("parse", [parse_calibration, parse_reality])
def test_the_settling_key_is_read_by_calibrations_and_realities(parse):
    twin = parse({"turntable": {"settling": SETTLING}})
    assert twin.turntable.settling == TurntableSettling(**SETTLING)
    assert parse({}).turntable.settling is None  # absent: the table stops dead
    # it changes what a simulation does, so it changes the hash, and it survives YAML
    assert twin_hash(twin) != twin_hash(parse({}))
    assert parse(yaml.safe_load(dump_yaml(twin))) == twin


@pytest.mark.parametrize(
    ("key", "value", "allowed"),
    [
        ("amplitude_deg", -0.1, "greater than or equal to 0"),
        ("amplitude_deg", 6.0, "less than or equal to 5"),
        ("frequency_hz", 0.0, "greater than or equal to 0.05"),
        ("frequency_hz", float("inf"), "finite"),
        ("damping_ratio", 0.0, "greater than or equal to 0.001"),
        ("damping_ratio", 1.0, "less than or equal to 0.9"),
    ],
)
def test_a_settling_out_of_range_is_refused_naming_field_and_range(key, value, allowed):
    with pytest.raises(InvalidInputError) as err:
        parse_reality({"turntable": {"settling": {**SETTLING, key: value}}})
    assert err.value.field == f"reality.turntable.settling.{key}"
    assert allowed in str(err.value)


def test_a_settling_needs_all_three_keys():
    with pytest.raises(InvalidInputError) as err:
        parse_calibration({"turntable": {"settling": {"amplitude_deg": 0.1}}})
    assert "calibration.turntable.settling." in err.value.field
    with pytest.raises(InvalidInputError, match="unknown field"):
        parse_calibration({"turntable": {"settling": {**SETTLING, "period_s": 1.0}}})


def test_the_ringing_is_the_damped_oscillation_of_the_key():
    s = TurntableSettling(**SETTLING)
    omega = 2 * math.pi * 2.5
    omega_d = omega * math.sqrt(1 - 0.08**2)
    t = np.array([0.0, 0.05, 0.3, 1.7])
    expected = 0.2 * np.exp(-0.08 * omega * t) * np.cos(omega_d * t)
    np.testing.assert_allclose(ringing_deg(s, t), expected, rtol=1e-12)
    assert damped_frequency_hz(s) == pytest.approx(omega_d / (2 * math.pi))
    # one damped period later the ringing is back in phase, smaller by exp(-zeta omega T_d)
    period_s = 1.0 / damped_frequency_hz(s)
    ratio = float(ringing_deg(s, period_s) / ringing_deg(s, 0.0))
    assert ratio == pytest.approx(math.exp(-0.08 * omega * period_s), rel=1e-9)
    assert float(ringing_deg(s, -0.01)) == 0.0


def test_the_settle_time_is_where_the_envelope_meets_the_tolerance():
    s = TurntableSettling(**SETTLING)
    t = settle_time_s(s, 0.001)
    assert float(envelope_deg(s, t)) == pytest.approx(0.001, rel=1e-9)
    assert float(envelope_deg(s, 0.99 * t)) > 0.001
    assert settle_time_s(None, 0.001) == 0.0
    assert settle_time_s(s, 0.2) == 0.0  # nothing above the tolerance: no wait


@pytest.mark.parametrize("tolerance", [0.0, -1.0, float("nan"), float("inf")])
def test_a_tolerance_that_is_not_a_positive_angle_is_refused(tolerance):
    with pytest.raises(InvalidInputError, match=r"tolerance_deg: .*allowed: a finite angle > 0"):
        settle_time_s(TurntableSettling(**SETTLING), tolerance)


@settings(max_examples=200, deadline=None)
@given(settlings, st.floats(-1e6, 1e9), st.floats(1e-12, 10.0))
def test_ringing_and_settle_time_are_finite_and_bounded_everywhere(s, t_s, tolerance_deg):
    ring = float(ringing_deg(s, t_s))
    env = float(envelope_deg(s, t_s))
    assert math.isfinite(ring) and math.isfinite(env)
    assert abs(ring) <= env + 1e-15 <= s.amplitude_deg + 1e-15
    wait = settle_time_s(s, tolerance_deg)
    assert math.isfinite(wait) and wait >= 0.0
    if wait > 0.0:
        assert float(envelope_deg(s, wait)) == pytest.approx(tolerance_deg, rel=1e-6)
