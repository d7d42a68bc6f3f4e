"""The suns -> lamp power calibration table: loading, interpolation, and refusing bad tables."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.errors import CalibrationError, LimitError
from drivers.solar_simulator import DEFAULT_CALIBRATION_PATH, SUNS_RANGE, SunsCalibration

pytestmark = pytest.mark.timeout(10)


def test_default_table_loads_and_covers_the_allowed_range():
    cal = SunsCalibration.load_default()
    assert cal.source == str(DEFAULT_CALIBRATION_PATH)
    assert cal.suns[0] <= SUNS_RANGE[0] and cal.suns[-1] >= SUNS_RANGE[1]
    assert cal.power_for(1.0) == 400.0
    assert cal.power_for(0.8) == 326.0


def test_linear_interpolation_between_points_and_its_inverse():
    cal = SunsCalibration((0.8, 1.0, 1.2), (320.0, 400.0, 500.0))
    assert cal.power_for(0.9) == pytest.approx(360.0)
    assert cal.power_for(1.1) == pytest.approx(450.0)
    assert cal.suns_for(450.0) == pytest.approx(1.1)
    assert cal.power_for(1.2) == 500.0  # the end points are inside the table


@given(st.floats(0.75, 1.25))
def test_power_then_suns_round_trips(suns):
    cal = SunsCalibration.load_default()
    assert cal.suns_for(cal.power_for(suns)) == pytest.approx(suns, abs=1e-12)


def test_outside_the_table_raises_naming_field_and_range():
    cal = SunsCalibration((0.8, 1.2), (320.0, 480.0), source="lab.yaml")
    with pytest.raises(LimitError, match=r"^suns: requested 1.3 suns .*\[0.8, 1.2\] suns"):
        cal.power_for(1.3)
    with pytest.raises(LimitError, match=r"^power_w: requested 500 W .*\[320, 480\] W"):
        cal.suns_for(500.0)
    assert cal.suns_for(520.0, extrapolate=True) == pytest.approx(1.3)


@pytest.mark.parametrize(
    ("suns", "power", "field", "why"),
    [
        ((0.8, 1.0, 0.9), (1.0, 2.0, 3.0), "calibration.suns", "increase strictly: 0.9 at index 2"),
        ((0.8, 1.0, 1.2), (330.0, 320.0, 400.0), "calibration.power_w", "at index 1 follows"),
        ((0.8, 1.0), (330.0, 330.0), "calibration.power_w", "increase strictly"),
        ((0.8,), (330.0,), "calibration.suns", "at least 2 points"),
        ((0.8, 1.0), (330.0, 400.0, 480.0), "calibration", "suns has 2 values, power_w 3"),
        ((0.8, float("nan")), (1.0, 2.0), "calibration.suns", "not a finite number > 0"),
        ((0.8, 1.0), (-1.0, 2.0), "calibration.power_w", "not a finite number > 0"),
    ],
)
def test_malformed_or_non_monotonic_tables_are_refused(suns, power, field, why):
    with pytest.raises(CalibrationError) as info:
        SunsCalibration(suns, power)
    assert info.value.field == field
    assert why in str(info.value)


def test_json_and_yaml_files(tmp_path):
    json_path = tmp_path / "cal.json"
    json_path.write_text(json.dumps({"suns": [0.8, 1.2], "power_w": [300, 500]}))
    yaml_path = tmp_path / "cal.yml"
    yaml_path.write_text("suns: [0.8, 1.2]\npower_w: [300, 500]\nnote: extra keys are ignored\n")
    for path in (json_path, yaml_path):
        cal = SunsCalibration.from_file(path)
        assert cal.power_for(1.0) == pytest.approx(400.0)
        assert cal.source == str(path)


def test_non_monotonic_file_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("suns: [0.8, 1.0, 1.2]\npower_w: [300, 420, 410]\n")
    with pytest.raises(CalibrationError, match=r"calibration\.power_w: .*index 2.*bad\.yaml"):
        SunsCalibration.from_file(path)


@pytest.mark.parametrize(
    ("name", "text", "why"),
    [
        ("cal.txt", "", "expected a .yaml, .yml or .json file"),
        ("cal.yaml", "- 1\n- 2\n", "does not hold a mapping"),
        ("cal.yaml", "suns: [0.8, 1.2]\n", "calibration.power_w: missing or not a list"),
        ("cal.json", '{"suns": "0.8", "power_w": [1, 2]}', "calibration.suns: missing or not"),
    ],
)
def test_unreadable_files_are_refused(tmp_path, name, text, why):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(CalibrationError, match=why):
        SunsCalibration.from_file(path)
