"""The simulated lab's world: frames rendered for the rig's state, in a reality."""

import numpy as np
import pytest

from drivers.camera.wire import get_use_case
from drivers.rig import RigState
from drivers.sim.rig import simulated_rig
from drivers.sim.usb_camera import CameraRequest
from drivers.sim.world import SimulatedWorld, default_reality
from sim_core.camera import Intrinsics, z_over_range
from sim_core.raw import reconstruct_raw
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import ObjectSpec, load_scene_spec
from sim_core.sensor import SensorParams
from sim_core.twin_file import parse_reality
from tests.sim_core.scenes import EXAMPLES

pytestmark = pytest.mark.timeout(120)
SATELLITE = EXAMPLES / "satellite_ground_test.yaml"
UC = get_use_case("MODE_5_45FPS_500")


def _world(reality=None, spp=2):
    return SimulatedWorld(load_scene_spec(SATELLITE), EXAMPLES,
                          RenderRequest(RenderSettings(integrator="direct", spp=spp),
                                        effects="all"), reality=reality)


def _request(index=0, angle=30.0, seed=3):
    return CameraRequest(UC, index, seed=seed,
                         rig_state=RigState(turntable_angle_deg=angle, solar_suns=1.0,
                                            shutter_open=True))


def _nominal_z_over_range(frame):
    h, w = frame.intensity.shape
    return z_over_range(Intrinsics(w, h, 208.33, 208.33, (w - 1) / 2, (h - 1) / 2))


@pytest.fixture(scope="module")
def rig():
    r = simulated_rig(frame_source=_world(), seed=3)
    yield r
    r.close()


def test_captured_frames_are_renders_of_the_satellite_at_about_one_metre(rig):
    rig.apply(RigState(turntable_angle_deg=30.0, solar_suns=1.0, shutter_open=True))
    frames = rig.capture(2)
    assert len(frames) == 2
    for f in frames:
        assert f.phase_images.shape == (1, 4, 171, 224) and f.phase_images.dtype == np.float32
        assert f.meta["rig"]["turntable_angle_deg"] == pytest.approx(30.0, abs=0.01)
    img = reconstruct_raw(frames[0], _nominal_z_over_range(frames[0]))
    centre = img.range_m[75:95, 100:124]
    assert np.nanmedian(centre) == pytest.approx(0.95, abs=0.1)
    # Different frames carry different noise.
    assert not np.array_equal(frames[0].phase_images, frames[1].phase_images)


def test_turning_the_table_changes_the_image(rig):
    rig.apply(RigState(turntable_angle_deg=0.0, solar_suns=1.0, shutter_open=True))
    a = rig.capture(1)[0]
    rig.apply(RigState(turntable_angle_deg=60.0, solar_suns=1.0, shutter_open=True))
    b = rig.capture(1)[0]
    body = np.s_[60:110, 90:135]
    assert np.abs(a.intensity[body] - b.intensity[body]).mean() > 1.0


def test_repeated_frames_of_a_state_differ_by_sensor_noise_only():
    """The mean of many frames converges to the noise-free exposure of one rendered field."""
    world = _world()
    frames = [world(_request(i)) for i in range(6)]
    c = np.stack([f.phase_images for f in frames]).astype(np.float64)
    # Pixel-wise spread of frames vs. the spread a fresh render per frame would add: a frozen
    # render leaves only the sensor noise, so the frame-to-frame variance of the bright object
    # equals the shot-noise prediction var(C) ~ intensity / gain (+ read noise).
    var = c.var(axis=0, ddof=1)[0, 0]
    mean_i = np.stack([f.intensity for f in frames]).mean(axis=0)
    sensor = SensorParams()  # the default sensor the simulated camera uses
    gain = sensor.adc_gain_e_per_dn
    bright = mean_i * gain > 5000.0  # [e-]
    read_dn2 = 2.0 * (sensor.read_noise_e / gain) ** 2  # both taps' read noise
    ratio = np.median(var[bright] / (mean_i[bright] / gain + read_dn2 + 2.0 / 12.0))
    assert ratio == pytest.approx(1.0, abs=0.2)


def test_the_reality_is_what_the_camera_sees():
    """A reality's principal point moves the image; its frames do not mention the reality."""
    nominal = _world(parse_reality({}))(_request())
    shifted = _world(parse_reality({"camera": {"cx_px": 111.5 + 6.0}}))(_request())
    a = nominal.intensity.astype(float)
    b = shifted.intensity.astype(float)
    cols = lambda img: (img.sum(axis=0) * np.arange(img.shape[1])).sum() / img.sum()  # noqa: E731
    assert cols(b) - cols(a) == pytest.approx(6.0, abs=1.0)
    assert set(shifted.meta) == {"source", "frame_index", "rig"}


def test_default_reality_differs_from_nominal_in_small_ways():
    spec = load_scene_spec(SATELLITE)
    r = default_reality(spec)
    assert r.turntable.zero_offset_deg == 0.5
    assert set(r.objects) == {o.name for o in spec.objects}


def test_mounting_other_objects_swaps_what_is_on_the_turntable():
    world = _world()
    before = world(_request())
    plate = ObjectSpec.model_validate({
        "name": "plate", "mesh": {"kind": "rectangle", "size_m": [0.3, 0.3]},
        "material": {"kind": "lambertian", "params": {"albedo": 0.8}},
        "pose": {"position_m": [0.0, 0.0, 0.15], "rotation_deg": [90.0, 0.0, 0.0]}})
    world.mount([plate])
    assert world.mounted == "plate"
    after = world(_request())
    img = reconstruct_raw(after, _nominal_z_over_range(after))
    assert np.nanmedian(img.range_m[70:100, 95:130]) == pytest.approx(1.0, abs=0.05)
    assert not np.array_equal(before.intensity, after.intensity)
    world.mount(None)
    assert world.mounted == "scene"
    again = world(_request())
    # the same scene again: only sensor noise differs, well under 50 e- per pixel on average
    gain = SensorParams().adc_gain_e_per_dn
    assert np.abs(again.intensity.astype(float) - before.intensity).mean() * gain < 50.0


# --- issue 27: the warm-up on the lab's clock, stray light ----------------------------------
WARM_UP = {"illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 5.0,
           "depth_drift_mm_per_c": 1.0}


def test_the_lab_clock_counts_frames_and_moves():
    from drivers.sim.lab_clock import LabClock

    clock = LabClock()
    assert clock.frame_time_s(30.0, 45.0) == 0.0
    assert clock.frame_time_s(30.0, 45.0) == pytest.approx(1 / 45)
    # 30 -> 150 deg at 20 deg/s and 80 deg/s^2: 0.25 s up, 5.75 s flat, 0.25 s down
    assert clock.frame_time_s(150.0, 45.0) == pytest.approx(2 / 45 + 6.25)
    assert clock.move_duration_s(0.0, 1.0) == pytest.approx(2 * (1.0 / 80) ** 0.5)  # triangle
    with pytest.raises(ValueError, match="frame_rate_hz"):
        clock.frame_time_s(0.0, 0.0)


def test_frames_report_the_warming_illumination_and_read_its_drift():
    from sim_core.warmup import illumination_temperature_c

    reality = parse_reality({"camera": {"temperature": WARM_UP}})
    world = _world(reality)
    dark = {"solar_suns": 0.0, "shutter_open": False}  # the camera's own light: less noise

    def frames(first_index, angle, n=6):
        return [world(CameraRequest(UC, first_index + i, seed=3, rig_state=RigState(
            turntable_angle_deg=angle, **dark))) for i in range(n)]

    def mean_range_m(batch):
        images = [reconstruct_raw(f, _nominal_z_over_range(f)) for f in batch]
        bright = np.all([im.valid for im in images], axis=0)
        return np.mean([im.range_m for im in images], axis=0), bright

    cold = frames(0, 30.0)
    frames(6, 150.0, n=1)  # a 6.25 s move there, another back: the lamp warms
    warm = frames(7, 30.0)
    t_warm = 7 / 45 + 6.25 + 6.25
    assert cold[0].illumination_temperature_c == 25.0
    assert warm[0].illumination_temperature_c == pytest.approx(
        illumination_temperature_c(t_warm, reality.camera.temperature))
    temps = [f.illumination_temperature_c for f in cold + warm]
    assert temps == sorted(temps)  # warming all along
    (a, va), (b, vb) = mean_range_m(cold), mean_range_m(warm)
    both = va & vb
    assert both.sum() > 1000
    drift_mm = np.median(b[both] - a[both]) * 1e3
    expect_mm = 1.0 * (np.mean(temps[6:]) - np.mean(temps[:6]))  # 1 mm/degC
    assert expect_mm > 15.0
    assert drift_mm == pytest.approx(expect_mm, abs=1.5)


def test_the_temperature_reaches_the_host_through_the_usb_wire():
    reality = parse_reality({"camera": {"temperature": WARM_UP}})
    with simulated_rig(frame_source=_world(reality), seed=3) as r:
        r.apply(RigState(turntable_angle_deg=30.0, solar_suns=1.0, shutter_open=True))
        frames = r.capture(2)
    temps = [f.illumination_temperature_c for f in frames]
    assert all(t is not None and 25.0 <= t < 45.0 for t in temps)
    assert temps[1] > temps[0]  # one frame period later, warmer


def test_stray_light_in_the_world_lights_the_dark_background():
    nominal = _world(parse_reality({}))(_request())
    stray = _world(parse_reality({"camera": {"stray_light": {"fraction": 0.03,
                                                              "kernel_radius_px": 60.0}}}))(
        _request())
    corner = np.s_[0:20, 0:30]  # background, far from the satellite
    gain = np.abs(stray.phase_images[0, 0][corner] - nominal.phase_images[0, 0][corner])
    assert np.mean(gain) > 2.0 * np.std(nominal.phase_images[0, 0][corner]) / np.sqrt(600)
    assert nominal.illumination_temperature_c is None  # no warm-up in this reality
