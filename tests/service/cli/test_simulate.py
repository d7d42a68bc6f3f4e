"""``toftwin simulate`` end to end: outputs, and bad input that writes nothing."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from service.cli import app

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
runner = CliRunner()

REQUIRED_ARRAYS = {
    "range_m", "depth_z_m", "amplitude", "intensity", "phase_rad", "valid", "frequencies_hz",
    "phasor", "dc_active", "dc_ambient", "truth_range_m", "truth_depth_z_m", "object_id", "hit",
}


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_simulate_writes_frame_files(tmp_path):
    out = tmp_path / "out"
    res = run("simulate", EXAMPLES / "satellite_ground_test.yaml", "--out", out, "--spp", 2,
              "--max-bounces", 2, "--seed", 3, "-q")
    assert res.exit_code == 0, res.output
    with np.load(out / "frame.npz") as z:
        assert set(z.files) >= REQUIRED_ARRAYS
        h, w = z["range_m"].shape
        assert (h, w) == (171, 224)
        assert z["phasor"].shape == (1, 171, 224) and z["phasor"].dtype == np.complex128
        assert np.all(np.isnan(z["range_m"][~z["valid"]]))
        assert np.all(np.isfinite(z["range_m"][z["valid"]]))
    meta = json.loads((out / "frame.json").read_text())
    assert len(meta["scene_hash"]) == 64
    assert meta["settings"]["spp"] == 2 and meta["settings"]["seed"] == 3
    assert {"render", "total"} <= set(meta["timings_s"])
    assert meta["package_version"]
    depth = np.array(Image.open(out / "depth.png"))
    grey = np.array(Image.open(out / "grey.png"))
    assert depth.dtype == np.uint16 and grey.dtype == np.uint8
    assert depth.shape == grey.shape == (171, 224)


def test_same_seed_gives_identical_files(tmp_path):
    for name in ("a", "b"):
        res = run("simulate", EXAMPLES / "corner.yaml", "--out", tmp_path / name, "--spp", 2, "-q")
        assert res.exit_code == 0, res.output
    with np.load(tmp_path / "a" / "frame.npz") as a, np.load(tmp_path / "b" / "frame.npz") as b:
        for k in a.files:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def _scene(tmp_path: Path, mutate) -> Path:
    data = yaml.safe_load((EXAMPLES / "plane.yaml").read_text())
    mutate(data)
    p = tmp_path / "scene.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def _mesh_object(path: str) -> dict:
    return {"name": "part", "mesh": {"kind": "file", "path": path}, "material": "black-flannel"}


BAD = {
    "unknown_field": (lambda d: d.update(colour="red"), "colour"),
    "negative_power": (lambda d: d["illumination"].update(power_w=-1.0), "illumination.power_w"),
    "nan_position": (
        lambda d: d["camera"]["pose"].update(position_m=[float("nan"), 0, 1]),
        "camera.pose.position_m",
    ),
    "zero_length_look_at": (
        lambda d: d["camera"]["pose"].update(look_at_m=[0.0, 0.0, 1.0]),
        "camera.pose.look_at_m",
    ),
    "missing_mesh_file": (
        lambda d: d["objects"].append(_mesh_object("nowhere.obj")), "objects[1].mesh.path"
    ),
    "bad_material_parameter": (
        lambda d: d["objects"][0].update(material={"kind": "lambertian",
                                                   "params": {"albedo": 1.5}}),
        "objects[0].material",
    ),
    "spp_out_of_range": (lambda d: d["render"].update(spp=0), "render.spp"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scene_exits_2_names_the_field_and_writes_nothing(tmp_path, case):
    mutate, field = BAD[case]
    scene = _scene(tmp_path, mutate)
    out = tmp_path / "out"
    res = run("simulate", scene, "--out", out, "-q")
    assert res.exit_code == 2, res.output
    assert field in res.output
    assert not out.exists()


@pytest.mark.parametrize(
    ("name", "text", "why"),
    [("bad.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "NaN"),
     ("empty.obj", "# nothing here\n", "empty")],
    ids=["nan_vertices", "empty"],
)
def test_a_bad_mesh_file_is_rejected(tmp_path, name, text, why):
    (tmp_path / name).write_text(text)
    scene = _scene(tmp_path, lambda d: d["objects"].append(_mesh_object(name)))
    res = run("simulate", scene, "--out", tmp_path / "out", "-q")
    assert res.exit_code == 2, res.output
    assert "objects[1].mesh" in res.output and why in res.output
    assert not (tmp_path / "out").exists()


def test_camera_inside_a_closed_mesh_is_rejected(tmp_path):
    box = {"name": "crate", "mesh": {"kind": "box", "size_m": [1.0, 1.0, 1.0]},
           "material": "black-flannel", "pose": {"position_m": [0.0, 0.0, 1.0]}}
    scene = _scene(tmp_path, lambda d: d["objects"].append(box))
    res = run("simulate", scene, "--out", tmp_path / "out", "-q")
    assert res.exit_code == 2, res.output
    assert "camera.pose.position_m" in res.output and "crate" in res.output
    assert not (tmp_path / "out").exists()


def test_bad_command_line_value_exits_2(tmp_path):
    res = run("simulate", EXAMPLES / "plane.yaml", "--out", tmp_path / "o", "--integrator", "bdpt")
    assert res.exit_code == 2
    assert "--integrator" in res.output


def test_explain_prints_every_effect_and_frame_json_records_the_plan(tmp_path):
    out = tmp_path / "out"
    res = run("simulate", EXAMPLES / "satellite_ground_test.yaml", "--out", out, "--spp", 2,
              "--explain", "-q")
    assert res.exit_code == 0, res.output
    meta = json.loads((out / "frame.json").read_text())
    plan = meta["effect_plan"]
    names = {e["name"] for e in plan["effects"]}
    assert {"multipath", "ambient", "sbi", "noise", "diffraction", "pixel_aperture"} <= names
    for e in plan["effects"]:
        assert e["name"] in res.output
        assert isinstance(e["enabled"], bool) and e["reason"] and e["cost_s"] >= 0.0
    assert {"plan", "render", "optics", "sensor", "reconstruct"} <= set(meta["timings_s"])
    assert (out / "raw.npz").exists()


def test_effects_all_turns_every_effect_on(tmp_path):
    out = tmp_path / "out"
    res = run("simulate", EXAMPLES / "plane.yaml", "--out", out, "--spp", 1, "--effects", "all",
              "--integrator", "path", "--max-bounces", 2, "-q")
    assert res.exit_code == 0, res.output
    plan = json.loads((out / "frame.json").read_text())["effect_plan"]
    on = {e["name"] for e in plan["effects"] if e["enabled"]}
    assert {"multipath", "sbi", "noise", "diffraction", "pixel_aperture"} <= on


def test_ideal_frame_has_no_raw_file_and_no_noise(tmp_path):
    for name in ("a", "b"):
        res = run("simulate", EXAMPLES / "plane.yaml", "--out", tmp_path / name, "--spp", 1,
                  "--ideal", "--seed", "1" if name == "a" else "2", "-q")
        assert res.exit_code == 0, res.output
    assert not (tmp_path / "a" / "raw.npz").exists()
    with np.load(tmp_path / "a" / "frame.npz") as a, np.load(tmp_path / "b" / "frame.npz") as b:
        # Without noise, two seeds differ only in where a pixel's single sample lands: by the
        # range gradient across a pixel (mm at the corners), not by noise (cm).
        diff = np.abs(a["range_m"] - b["range_m"])
        assert np.median(diff) < 1e-3 and diff.max() < 1e-2


def test_simulate_applies_a_calibration_file(tmp_path):
    """A calibration's phase offset shifts the depth; a bad file is exit 2 naming the field."""
    cal = tmp_path / "calibration.yaml"
    # 0.1 rad at 60.24 MHz is 39.6 mm of range.
    cal.write_text("camera:\n  depth: {phase_offset_rad: [0.1]}\n")
    base, shifted = tmp_path / "a", tmp_path / "b"
    for out, extra in ((base, ()), (shifted, ("--calibration", cal))):
        res = run("simulate", EXAMPLES / "plane.yaml", "--out", out, "--spp", 2, "-q", *extra)
        assert res.exit_code == 0, res.output
    assert json.loads((base / "frame.json").read_text())["calibration_hash"] is None
    assert len(json.loads((shifted / "frame.json").read_text())["calibration_hash"]) == 16
    with np.load(base / "frame.npz") as a, np.load(shifted / "frame.npz") as b:
        ok = a["valid"] & b["valid"]
        diff = np.median((b["range_m"] - a["range_m"])[ok])
    assert diff == pytest.approx(0.0396, abs=0.002)
    cal.write_text("camera:\n  depth: {phase_offset_rad: [7.0]}\n")
    res = run("simulate", EXAMPLES / "plane.yaml", "--out", tmp_path / "c", "-q",
              "--calibration", cal)
    assert res.exit_code == 2
    assert "calibration.camera.depth.phase_offset_rad[0]" in " ".join(res.output.split())
    assert not (tmp_path / "c").exists()


def test_noise_fraction_records_its_target_and_what_it_reached(tmp_path):
    """The plane (direct light, 1 spp) rendered to a fraction of the sensor's noise: frame.json
    records the target and the spp spent; a value out of range is exit 2 naming the option."""
    out = tmp_path / "out"
    res = run("simulate", EXAMPLES / "plane.yaml", "--out", out, "--spp", 1,
              "--noise-fraction", 0.5, "-q")
    assert res.exit_code == 0, res.output
    adaptive = json.loads((out / "frame.json").read_text())["adaptive"]
    assert adaptive["target_noise_fraction"] == 0.5
    assert adaptive["achieved_noise_fraction"] <= 0.5
    assert adaptive["spp_min"] >= 1 and adaptive["fraction_meeting_target"] == 1.0
    assert "of the sensor's noise" in res.output
    for bad in (0.0, 3.0):
        res = run("simulate", EXAMPLES / "plane.yaml", "--out", tmp_path / "bad", "-q",
                  "--noise-fraction", bad)
        assert res.exit_code == 2
        assert "--noise-fraction" in res.output
        assert not (tmp_path / "bad").exists()
