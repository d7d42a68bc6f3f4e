"""Calibration and reality files: validation, hashing, and their effect on a built scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim_core.errors import InvalidInputError
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from sim_core.twin_file import (
    ObjectTwinFile,
    dump_yaml,
    load_calibration,
    load_reality,
    parse_calibration,
    parse_reality,
    twin_hash,
    with_object_twin,
    write_calibration,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
ISSUE_REALITY = {
    "camera": {
        "fx_px": 211.4, "fy_px": 210.7, "cx_px": 113.1, "cy_px": 84.2,
        "distortion": {"k1": -0.11, "k2": 0.04, "p1": 0.0005, "p2": -0.0004, "k3": 0.0},
        "depth": {
            "phase_offset_rad": [0.03],
            "wiggling": [{"harmonic": 4, "amplitude_rad": 0.015, "phase_rad": 0.6}],
            "pixel_offset_m": {"sigma": 0.004, "correlation_px": 12, "seed": 5},
        },
        "sensor": {"adc_gain_e_per_dn": 9.0, "read_noise_e": 30.0},
    },
    "illumination": {"power_w": 1.35},
    "turntable": {"axis_point_m": [0.004, -0.002, 0.0], "axis_direction": [0.01, 0.02, 0.9997],
                  "zero_offset_deg": 0.7},
    "solar_simulator": {"irradiance_scale": 1.06},
    "mount": {"pose_offset": {"position_m": [0.003, 0.0, -0.002], "rotation_deg": [0, 0, 0.8]}},
    "objects": {"body": {"reflectance_scale": 0.92}},
}


def test_the_issues_example_reality_is_valid():
    r = parse_reality(ISSUE_REALITY)
    assert r.camera.depth.wiggling[0].harmonic == 4
    assert r.objects["body"].reflectance_scale == 0.92


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"camera": {"fx_px": -1}}, "calibration.camera.fx_px"),
        ({"camera": {"depth": {"wiggling": [{"harmonic": 0, "amplitude_rad": 0.01}]}}},
         "calibration.camera.depth.wiggling[0].harmonic"),
        ({"camera": {"sensor": {"adc_gain_e_per_dn": 0}}},
         "calibration.camera.sensor.adc_gain_e_per_dn"),
        ({"turntable": {"zero_offset_deg": float("nan")}}, "calibration.turntable.zero_offset_deg"),
        ({"colour": 1}, "calibration.colour"),
        ({"mount": {}}, "calibration.mount"),  # a reality key is not a calibration key
        ({"camera": {"image_size_px": [640, 0]}}, "calibration.camera.image_size_px[1]"),
        ({"camera": {"image_size_px": [20000, 480]}}, "calibration.camera.image_size_px[0]"),
        # a lens is checked against the file's image: 342 px lies outside 224 x 171
        ({"camera": {"cx_px": 342.5}}, "calibration.camera.cx_px"),
        ({"camera": {"image_size_px": [320, 240], "cx_px": 342.5}}, "calibration.camera.cx_px"),
    ],
)
def test_bad_values_name_the_field(data, field):
    with pytest.raises(InvalidInputError) as err:
        parse_calibration(data)
    assert err.value.field == field


def test_a_calibration_of_another_image_is_checked_against_it_and_hashed_apart():
    lens = {"fx_px": 533.0, "fy_px": 533.2, "cx_px": 342.5, "cy_px": 233.9}
    cal = parse_calibration({"camera": {"image_size_px": [640, 480], **lens}})
    assert cal.camera.image_size_px == (640, 480)
    preset = parse_calibration({"camera": {"fx_px": 210.0}})
    assert twin_hash(preset) == twin_hash(parse_calibration(
        {"camera": {"fx_px": 210.0, "image_size_px": None}}))  # absent and null: one hash
    assert twin_hash(preset) != twin_hash(parse_calibration(
        {"camera": {"fx_px": 210.0, "image_size_px": [224, 171]}}))


def test_hash_ignores_provenance_but_not_values(tmp_path):
    a = parse_calibration({"camera": {"fx_px": 210.0}, "provenance": {"rig": "lab 1"}})
    b = parse_calibration({"camera": {"fx_px": 210.0}})
    c = parse_calibration({"camera": {"fx_px": 210.5}})
    assert twin_hash(a) == twin_hash(b) != twin_hash(c)
    path = write_calibration(tmp_path / "calibration.yaml", a)
    assert load_calibration(path) == a
    assert "provenance" in dump_yaml(a)


def test_a_reality_changes_the_built_scene_as_the_conventions_say():
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    reality = parse_reality(ISSUE_REALITY)
    nominal = build_scene(spec, EXAMPLES, turntable_deg=30.0, solar_suns=1.0)
    real = build_scene(spec, EXAMPLES, turntable_deg=30.0, solar_suns=1.0, twin=reality)
    assert real.camera.intrinsics.fx_px == 211.4
    assert real.camera.intrinsics.distortion[0] == -0.11
    assert real.light.power_w == 1.35
    assert real.sensor.adc_gain_e_per_dn == 9.0
    expect = 1.06 * nominal.ambient[0].irradiance_w_m2
    assert real.ambient[0].irradiance_w_m2 == pytest.approx(expect)
    body = real.object_names.index("body")
    assert real.materials[body] != nominal.materials[body]
    assert real.depth_errors is not None and real.depth_errors.pixel_offsets_m.shape == (171, 224)
    assert real.twin_hash == twin_hash(reality) and nominal.twin_hash is None
    assert real.scene_hash != nominal.scene_hash
    # The background does not move; the mounted objects do (mount offset, axis, zero offset).
    bg = np.asarray(real.object_index) == real.object_names.index("background")
    assert np.array_equal(real.triangles_m[bg], nominal.triangles_m[bg])
    moved = np.asarray(real.object_index) == body
    shift = np.abs(real.triangles_m[moved] - nominal.triangles_m[moved]).max()
    assert 1e-3 < shift < 0.02


def test_zero_offset_is_added_to_the_reported_angle():
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    twin = parse_calibration({"turntable": {"zero_offset_deg": 0.7}})
    a = build_scene(spec, EXAMPLES, turntable_deg=30.0, twin=twin)
    b = build_scene(spec, EXAMPLES, turntable_deg=30.7)
    assert np.allclose(a.triangles_m, b.triangles_m)


def test_a_scene_applies_the_calibration_it_references(tmp_path):
    spec = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
    write_calibration(tmp_path / "cal.yaml", parse_calibration({"camera": {"cy_px": 86.0}}))
    spec = spec.model_copy(update={"calibration": "cal.yaml"})
    scene = build_scene(spec, tmp_path)  # no mesh files: the base dir only resolves the file
    assert scene.camera.intrinsics.cy_px == 86.0 and scene.twin_hash is not None
    missing = spec.model_copy(update={"calibration": "nope.yaml"})
    with pytest.raises(InvalidInputError, match="does not exist"):
        build_scene(missing, tmp_path)


# --- issue 27: the camera's warm-up drift and stray light ------------------------------------
WARMUP = {"illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 600.0,
          "depth_drift_mm_per_c": 0.4}


def test_warmup_and_stray_light_keys_are_read_by_realities_and_calibrations():
    data = {"camera": {"temperature": WARMUP,
                       "stray_light": {"fraction": 0.02, "kernel_radius_px": 40.0}}}
    cal, reality = parse_calibration(data), parse_reality(data)
    assert cal.camera.temperature == reality.camera.temperature
    assert cal.camera.temperature.depth_drift_mm_per_c == [0.4]  # one number: all frequencies
    assert reality.camera.stray_light.kernel_radius_px == 40.0
    per_f = parse_calibration({"camera": {"temperature": {**WARMUP,
                                                          "depth_drift_mm_per_c": [0.3, 0.5]}}})
    assert per_f.camera.temperature.depth_drift_mm_per_c == [0.3, 0.5]
    assert twin_hash(cal) != twin_hash(per_f)
    assert parse_calibration({}).camera.temperature is None  # absent: the effect is off
    assert parse_calibration({}).camera.stray_light is None


@pytest.mark.parametrize(
    ("camera", "field", "allowed"),
    [
        ({"temperature": {**WARMUP, "time_constant_s": 0}}, "temperature.time_constant_s",
         "greater than 0"),
        ({"temperature": {**WARMUP, "illumination_end_c": 300}},
         "temperature.illumination_end_c", "125"),
        ({"temperature": {**WARMUP, "depth_drift_mm_per_c": [0.1, 30.0]}},
         "temperature.depth_drift_mm_per_c[1]", "20"),
        ({"temperature": {**WARMUP, "depth_drift_mm_per_c": [0.1] * 5}},
         "temperature.depth_drift_mm_per_c", "at most 4"),
        ({"temperature": {k: v for k, v in WARMUP.items() if k != "time_constant_s"}},
         "temperature.time_constant_s", "required"),
        ({"stray_light": {"fraction": 0.6, "kernel_radius_px": 30}}, "stray_light.fraction",
         "0.5"),
        ({"stray_light": {"fraction": 0.01, "kernel_radius_px": -1}},
         "stray_light.kernel_radius_px", "greater than or equal to 0"),
        ({"stray_light": {"fraction": float("nan"), "kernel_radius_px": 1}},
         "stray_light.fraction", "finite"),
    ],
)
def test_bad_warmup_and_stray_light_values_name_the_field_and_range(camera, field, allowed):
    with pytest.raises(InvalidInputError) as err:
        parse_reality({"camera": camera})
    assert err.value.field == f"reality.camera.{field}"
    assert allowed in str(err.value)


# --- issue 27: the rest a calibration asks for after every move -------------------------------
def test_a_calibration_keeps_its_rest_after_a_move_and_a_reality_file_refuses_it(tmp_path):
    cal = parse_calibration({"turntable": {"rest_after_move_s": 120.0}})
    assert cal.turntable.rest_after_move_s == 120.0 and cal.turntable.settling is None
    assert twin_hash(cal) != twin_hash(parse_calibration({}))
    assert parse_calibration({}).turntable.rest_after_move_s is None  # absent: no rest
    path = tmp_path / "cal.yaml"
    write_calibration(path, cal)
    assert load_calibration(path).turntable.rest_after_move_s == 120.0
    reality = tmp_path / "reality.yaml"
    reality.write_text("turntable:\n  rest_after_move_s: 120.0\n")
    with pytest.raises(InvalidInputError) as err:
        load_reality(reality)
    assert err.value.field == "reality.turntable.rest_after_move_s"
    assert "turntable.settling" in str(err.value)
    # a calibration combined with an object file keeps it (what the service's campaigns wait by)
    both = with_object_twin(cal, ObjectTwinFile())
    assert both.turntable.rest_after_move_s == 120.0


@pytest.mark.parametrize("value", [0.0, -5.0, 3601.0, float("inf")])
def test_a_rest_after_a_move_out_of_range_names_the_field(value):
    with pytest.raises(InvalidInputError) as err:
        parse_calibration({"turntable": {"rest_after_move_s": value}})
    assert err.value.field == "calibration.turntable.rest_after_move_s"
