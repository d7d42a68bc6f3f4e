"""The warm-up drift measured from a warm-up sequence of a fixed target (issue 27).

The simulated lab warms its illumination as a random reality says; the estimator sees only the
frames and their reported temperatures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration.warmup import DRIFT_KEY, fit_warmup
from drivers.camera.wire import get_use_case
from drivers.rig import RigState
from drivers.sim.usb_camera import CameraRequest
from drivers.sim.world import SimulatedWorld
from sim_core.errors import InvalidInputError
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import parse_scene_spec
from tests.calibration.realities import random_reality, with_camera_effects

pytestmark = pytest.mark.timeout(120)
UC = get_use_case("MODE_9_5FPS_2000")  # two frequencies, a long exposure
WALL = {
    "camera": {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 1, 0], "up": [0, 0, 1]}},
    "illumination": {"power_w": 1.0},
    "objects": [{"name": "wall", "mesh": {"kind": "rectangle", "size_m": [3.0, 3.0]},
                 "material": {"kind": "lambertian", "params": {"albedo": 0.9}},
                 "pose": {"position_m": [0.0, 0.6, 0.0], "rotation_deg": [90, 0, 0]}}],
}
PATCH = np.zeros((171, 224), bool)
PATCH[45:125, 62:162] = True


def warmup_sequence(world: SimulatedWorld, n: int = 12, pause_s: float = 100.0) -> list:
    """``n`` frames of the fixed wall, ``pause_s`` of the lab's time apart."""
    state = RigState(turntable_angle_deg=0.0, solar_suns=0.0, shutter_open=False)
    frames = []
    for i in range(n):
        frames.append(world(CameraRequest(UC, i, seed=7, rig_state=state)))
        world.clock.wait(pause_s)
    return frames


@pytest.mark.parametrize("seed", [1, 2, 5])
def test_the_drift_of_a_random_reality_is_measured_within_ten_percent(seed):
    reality = with_camera_effects(random_reality(seed), seed)
    reality = reality.model_copy(update={"camera": reality.camera.model_copy(
        update={"stray_light": None})})  # a fixed wall: only the warm-up changes
    world = SimulatedWorld(parse_scene_spec(WALL), ".", RenderRequest(
        RenderSettings(integrator="direct", spp=2), effects="auto"), reality=reality)
    fit = fit_warmup(warmup_sequence(world), PATCH)
    truth = reality.camera.temperature.depth_drift_mm_per_c[0]
    assert fit.verdict.determined, fit.verdict
    np.testing.assert_allclose(fit.drift_mm_per_c, truth, rtol=0.10)  # both frequencies
    assert np.all(np.abs(fit.drift_mm_per_c - truth) < 3.0 * fit.drift_std_mm_per_c)
    assert fit.temperatures_c[-1] - fit.temperatures_c[0] > 10.0
    key = fit.temperature_key(25.0, 45.0, 600.0)
    assert key["depth_drift_mm_per_c"] == [round(float(k), 4) for k in fit.drift_mm_per_c]
    assert DRIFT_KEY.endswith("depth_drift_mm_per_c")


def _frames_at(temperatures, drift_mm_per_c=0.5, noise_mm=0.0, seed=0):
    """Synthetic frames of a patch whose range follows the temperatures, with range noise."""
    rng = np.random.default_rng(seed)
    f = 60.24e6
    out = []
    for t in temperatures:
        r_m = 1.0 + drift_mm_per_c * 1e-3 * (t - 25.0) + rng.normal(0, noise_mm * 1e-3,
                                                                      (171, 224))
        phi = 4 * np.pi * f * r_m / 299_792_458.0
        c = np.stack([100 * np.cos(phi + k * np.pi / 2) for k in range(4)])[None]
        out.append(dataclasses.replace(_blank(), phase_images=c.astype(np.float32),
                                       illumination_temperature_c=float(t)))
    return out


def _blank():
    from sim_core.raw import RawFrame

    return RawFrame(np.zeros((1, 4, 171, 224), np.float32), np.zeros((171, 224), np.float32),
                    np.array([60.24e6]), np.zeros((171, 224), bool), np.zeros((171, 224), bool),
                    500e-6)


def test_noise_free_frames_give_the_exact_drift_and_a_flat_sequence_is_not_determined():
    fit = fit_warmup(_frames_at(np.linspace(25, 40, 6)), PATCH)
    assert fit.drift_mm_per_c[0] == pytest.approx(0.5, rel=1e-4) and fit.verdict.determined
    flat = fit_warmup(_frames_at([30.0, 30.5, 31.0]), PATCH)
    assert flat.verdict.verdict == "not determined" and "span" in flat.verdict.reason
    same = fit_warmup(_frames_at([30.0, 30.0, 30.0]), PATCH)  # no span: no division by zero
    assert same.verdict.verdict == "not determined" and np.isnan(same.drift_mm_per_c[0])


def test_a_sequence_the_line_does_not_explain_is_unexplained():
    temps = np.linspace(25, 40, 10)
    frames = _frames_at(temps, noise_mm=2.0)
    # a jump of 3 mm half way, which no drift explains (the target moved)
    frames = frames[:5] + [dataclasses.replace(f, phase_images=np.roll(
        f.phase_images, 0)) for f in _frames_at(temps[5:] + 6.0, noise_mm=2.0, seed=1)]
    for i in range(5, 10):
        frames[i] = dataclasses.replace(frames[i], illumination_temperature_c=float(temps[i]))
    fit = fit_warmup(frames, PATCH)
    assert fit.verdict.verdict == "unexplained" and "chi-square" in fit.verdict.reason


def test_bad_input_names_the_field():
    frames = _frames_at([25.0, 30.0, 35.0])
    with pytest.raises(InvalidInputError, match=r"frames\[1\].illumination_temperature_c"):
        fit_warmup([frames[0], dataclasses.replace(frames[1], illumination_temperature_c=None),
                    frames[2]], PATCH)
    with pytest.raises(InvalidInputError, match="at least 3"):
        fit_warmup(frames[:2], PATCH)
    with pytest.raises(InvalidInputError, match="patch"):
        fit_warmup(frames, np.zeros((171, 224), bool))


def test_an_averaged_capture_keeps_its_frames_mean_temperature():
    from calibration.captures import average_frames

    frames = _frames_at([30.0, 31.0, 32.5])
    assert average_frames(frames).illumination_temperature_c == pytest.approx(31.1666666)
    # one frame without a report: the mean is not known
    frames[1] = dataclasses.replace(frames[1], illumination_temperature_c=None)
    assert average_frames(frames).illumination_temperature_c is None
