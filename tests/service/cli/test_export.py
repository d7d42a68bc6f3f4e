"""``toftwin export calibration``: a calibration's camera as OpenCV's FileStorage YAML (read back
with ``cv2.FileStorage``) and as ROS's camera_info YAML (read back as ROS's parser reads it: plain
YAML, matrices row-major), for a whole calibration, one holding only part of the lens, and a
photo calibration of another camera's image."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibration.camera_forms import calibrated_intrinsics
from service.cli import app
from sim_core.camera import CAMERA_PRESETS
from sim_core.twin_file import parse_calibration
from tests.service.api.test_calibration import CALIBRATION

runner = CliRunner()
PRESET = CAMERA_PRESETS["pmd-camboard-pico-flexx"]


def _export(tmp_path, calibration: dict, to: str, name: str = "out.yml", *extra: str):
    src = tmp_path / "calibration.yaml"
    src.write_text(yaml.safe_dump(calibration))
    out = tmp_path / name
    res = runner.invoke(app, ["export", "calibration", str(src), "--to", to, "--out", str(out),
                              *extra])
    return res, out


def _expected(calibration: dict) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    cam = calibration.get("camera", {})
    k = np.array([[cam.get("fx_px", PRESET["fx_px"]), 0, cam.get("cx_px", PRESET["cx_px"])],
                  [0, cam.get("fy_px", PRESET["fy_px"]), cam.get("cy_px", PRESET["cy_px"])],
                  [0, 0, 1]], dtype=float)
    d = cam.get("distortion", {})
    dist = np.array([[d.get(n, 0.0) for n in ("k1", "k2", "p1", "p2", "k3")]])
    size = tuple(cam.get("image_size_px", (PRESET["width_px"], PRESET["height_px"])))
    return k, dist, size


PARTIAL = {"camera": {"fx_px": 212.5, "depth": {"phase_offset_rad": [0.01]}}}
PHOTO = {"camera": {"image_size_px": [640, 480], "fx_px": 533.1, "fy_px": 533.2,
                    "cx_px": 342.5, "cy_px": 233.9,
                    "distortion": {"k1": -0.28, "k2": 0.09, "p1": 1e-3, "p2": -2e-4, "k3": 0.0}}}


@pytest.mark.parametrize("calibration", [CALIBRATION, PARTIAL, PHOTO],
                         ids=["whole", "partial", "another camera"])
def test_opencv_reads_the_camera_matrix_of_the_calibration(tmp_path, calibration):
    res, out = _export(tmp_path, calibration, "opencv")
    assert res.exit_code == 0, res.output
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    try:
        k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
        size = (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real()))
    finally:
        fs.release()
    want_k, want_d, want_size = _expected(calibration)
    assert np.array_equal(k, want_k) and np.array_equal(d, want_d) and size == want_size
    # the twin's camera is the one exported: a pixel's ray undistorts alike
    intr = calibrated_intrinsics(parse_calibration(calibration))
    assert (intr.width_px, intr.height_px) == size and intr.fx_px == k[0, 0]
    assert [p.name for p in tmp_path.iterdir() if "partial" in p.name] == []


@pytest.mark.parametrize("calibration", [CALIBRATION, PHOTO], ids=["whole", "another camera"])
def test_ros_camera_info_holds_the_calibration(tmp_path, calibration):
    res, out = _export(tmp_path, calibration, "ros", "camera_info.yaml", "--camera-name",
                       "flexx_1")
    assert res.exit_code == 0, res.output
    info = yaml.safe_load(out.read_text())
    want_k, want_d, want_size = _expected(calibration)
    assert (info["image_width"], info["image_height"]) == want_size
    assert info["camera_name"] == "flexx_1" and info["distortion_model"] == "plumb_bob"

    def mat(name):
        m = info[name]
        return np.array(m["data"], dtype=float).reshape(m["rows"], m["cols"])

    assert np.array_equal(mat("camera_matrix"), want_k)
    assert np.array_equal(mat("distortion_coefficients"), want_d)
    assert np.array_equal(mat("rectification_matrix"), np.eye(3))
    p = mat("projection_matrix")
    assert p.shape == (3, 4) and np.array_equal(p[:, :3], want_k) and not p[:, 3].any()
    # a point in the camera frame projects alike through ROS's P (undistorted) and OpenCV's K
    xyz = np.array([0.1, -0.05, 1.2])
    uvw = p @ np.append(xyz, 1.0)
    cv_uv = cv2.projectPoints(xyz.reshape(1, 3), np.zeros(3), np.zeros(3), want_k,
                              np.zeros(5))[0].ravel()
    assert np.allclose(uvw[:2] / uvw[2], cv_uv)


@pytest.mark.parametrize(("args", "says"), [
    (["--to", "matlab"], "--to: 'matlab'; allowed: opencv, ros"),
    (["--to", "opencv", "--camera-name", " "], "--camera-name"),
])
def test_bad_options_name_the_option(tmp_path, args, says):
    src = tmp_path / "calibration.yaml"
    src.write_text(yaml.safe_dump(CALIBRATION))
    res = runner.invoke(app, ["export", "calibration", str(src), "--out",
                              str(tmp_path / "o.yml"), *args])
    assert res.exit_code == 2 and says in " ".join(res.stderr.split()), res.stderr
    assert not (tmp_path / "o.yml").exists()


def test_an_existing_file_is_kept_unless_forced_and_a_lens_without_its_image_is_refused(
        tmp_path):
    res, out = _export(tmp_path, CALIBRATION, "opencv")
    assert res.exit_code == 0
    before = out.read_bytes()
    res, _ = _export(tmp_path, PARTIAL, "opencv")
    assert res.exit_code == 2 and "--out" in res.stderr and "--force" in res.stderr
    assert out.read_bytes() == before  # nothing stored is lost
    res, _ = _export(tmp_path, PARTIAL, "opencv", "out.yml", "--force")
    assert res.exit_code == 0 and out.read_bytes() != before
    # a lens measured on another image, without its focal length: the preset's is no answer
    other = {"camera": {"image_size_px": [640, 480], "cx_px": 320.0, "cy_px": 240.0}}
    res, out = _export(tmp_path, other, "ros", "other.yaml")
    assert res.exit_code == 2 and "camera.fx_px" in res.stderr and "640 x 480" in res.stderr
    assert not out.exists()
    res, _ = _export(tmp_path, CALIBRATION, "opencv", "o.json")
    assert res.exit_code == 2 and ".yml or .yaml" in res.stderr


@pytest.mark.parametrize("case", ["folder", "parent is a file", "the source", "camera name"])
def test_an_out_that_is_no_file_to_write_is_refused_naming_it(tmp_path, case):
    src = tmp_path / "calibration.yaml"
    src.write_text(yaml.safe_dump(CALIBRATION))
    before = src.read_bytes()
    extra: list[str] = ["--force"]
    if case == "folder":
        out, says = tmp_path / "dir.yml", "is a folder"
        out.mkdir()
    elif case == "parent is a file":
        (tmp_path / "f.yml").write_text("x")
        out, says = tmp_path / "f.yml" / "x.yml", "is a file, not a folder"
    elif case == "the source":
        src = src.rename(tmp_path / "calibration.yml")
        out, says = src, "is the calibration it is made from"
    else:
        out, says = tmp_path / "c.yml", "--camera-name"
        extra = ["--camera-name", "pico-flexx"]
    res = runner.invoke(app, ["export", "calibration", str(src), "--to", "ros", "--out",
                              str(out), *extra])
    assert res.exit_code == 2, (res.stdout, res.stderr)
    assert says in " ".join(res.stderr.split()) and res.stdout == "", res.stderr
    assert src.read_bytes() == before
