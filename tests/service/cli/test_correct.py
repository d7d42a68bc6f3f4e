"""``toftwin correct``: a measured frame with a calibration's depth errors, corrected."""

from __future__ import annotations

import dataclasses

import numpy as np
from typer.testing import CliRunner

from service.cli import app
from sim_core import frame_io
from sim_core.pipeline import expose_light, render_light, simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from sim_core.twin_file import parse_calibration, write_calibration
from tests.sim_core.scenes import EXAMPLES

CAL = {"camera": {"depth": {
    "phase_offset_rad": [0.05],
    "wiggling": [{"harmonic": 3, "amplitude_rad": 0.038, "phase_rad": 0.4}],
    "pixel_offset_m": {"sigma": 0.004, "correlation_px": 10, "seed": 3}}}}


def _corrected(tmp_path, spec, settings, cal, raw):
    """``raw`` written as a measured frame and corrected by ``toftwin correct`` with ``cal``:
    the ideal simulation of the nominal scene and the corrected frame."""
    truth = simulate(build_scene(spec, EXAMPLES), RenderRequest(settings, ideal=True))
    frame_io.write_measured(tmp_path / "m", raw, build_scene(spec, EXAMPLES).camera, {})
    write_calibration(tmp_path / "cal.yaml", cal)
    res = CliRunner().invoke(app, ["correct", str(tmp_path / "m"), "--calibration",
                                   str(tmp_path / "cal.yaml")])
    assert res.exit_code == 0, res.output
    return truth, frame_io.read_measured(tmp_path / "m-corrected")


def test_correct_removes_the_depth_errors(tmp_path):
    spec = load_scene_spec(EXAMPLES / "plane.yaml")
    cal = parse_calibration(CAL)
    settings = RenderSettings(integrator="direct", spp=4, seed=1)
    # The sensor's mean response (no shot or read noise): what is left after the correction
    # is then the correction's own error, not noise of dim pixels that decides an RMS.
    scene = build_scene(spec, EXAMPLES, twin=cal)
    measured = expose_light(scene, render_light(scene, RenderRequest(settings)), noise=False)
    truth, fixed = _corrected(tmp_path, spec, settings, cal, measured.raw)
    ok = fixed.image.valid & truth.image.valid & measured.image.valid
    before = (measured.image.range_m - truth.image.range_m)[ok]
    after = (fixed.image.range_m - truth.image.range_m)[ok]
    assert np.sqrt(np.mean(before**2)) > 0.01  # offset, wiggling and fixed pattern: ~12 mm
    rms = lambda e: np.sqrt(np.mean(e**2))  # noqa: E731
    assert abs(np.median(after)) < 0.001 and rms(after) < 0.1 * rms(before)
    assert fixed.meta["corrected"]["calibration_hash"]
    # The input is never overwritten, an existing output needs --force.
    again = CliRunner().invoke(app, ["correct", str(tmp_path / "m"), "--calibration",
                                     str(tmp_path / "cal.yaml")])
    assert again.exit_code == 2 and "--force" in again.output


def test_a_bad_calibration_is_exit_2_naming_the_field(tmp_path):
    bad = tmp_path / "cal.yaml"
    bad.write_text("camera: {depth: {phase_offset_rad: [9]}}\n")
    res = CliRunner().invoke(app, ["correct", str(tmp_path), "--calibration", str(bad)])
    assert res.exit_code == 2
    assert "calibration.camera.depth.phase_offset_rad[0]" in " ".join(res.output.split())


def test_correct_removes_the_warm_up_drift_at_the_frames_temperature(tmp_path):
    spec = load_scene_spec(EXAMPLES / "plane.yaml")
    warm = {"illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 600.0,
            "depth_drift_mm_per_c": 0.6}
    cal = parse_calibration({"camera": {**CAL["camera"], "temperature": warm}})
    settings = RenderSettings(integrator="direct", spp=4, seed=1)
    scene = build_scene(spec, EXAMPLES, twin=cal, illumination_temperature_c=40.0)
    measured = expose_light(scene, render_light(scene, RenderRequest(settings)), noise=False)
    # the camera reports the temperature it exposed the frame at (the simulated lab's world does)
    raw = dataclasses.replace(measured.raw, illumination_temperature_c=40.0)
    truth, fixed = _corrected(tmp_path, spec, settings, cal, raw)
    ok = fixed.image.valid & truth.image.valid & measured.image.valid
    before = np.median((measured.image.range_m - truth.image.range_m)[ok])
    after = np.median((fixed.image.range_m - truth.image.range_m)[ok])
    assert before > 0.006  # 9 mm of drift at 40 degC, with the offset's few mm
    assert abs(after) < 0.001
    assert fixed.meta["corrected"]["warm_up_drift"].startswith("removed at 40.00 degC")
