"""The rig's ophyd-async devices on the device simulators, driven by Bluesky's RunEngine.

The turntable reads back the angles it was sent to and refuses targets outside the
controller's limits before anything moves; the solar simulator's level lights the lamp, sets
and puts it out, refuses levels outside 0 / 0.8..1.2 sun and does not relight a lamp that went
out behind its back; the camera's failures reach the plan as the driver's own error. The
camera simulator's plane stands in front of the camera here (no rendering): the scan with the
rendered scene is tests/drivers/bluesky/test_scan.py.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import bluesky.plan_stubs as bps
import bluesky.plans as bp
import h5py
import numpy as np
import pytest
from bluesky import RunEngine
from bluesky.run_engine import call_in_bluesky_event_loop
from bluesky.simulators import check_limits
from bluesky.utils import FailedStatus
from ophyd_async.core import StaticFilenameProvider, StaticPathProvider
from ophyd_async.plan_stubs import ensure_connected

from drivers.bluesky.rig_devices import RigDevices, rig_devices
from drivers.bluesky.simulated import simulated_devices
from drivers.camera import UsbCameraSettings
from drivers.errors import DeviceTimeoutError, LampFaultError, LimitError
from drivers.sim.rig import simulated_rig

pytestmark = [pytest.mark.bluesky, pytest.mark.timeout(120)]


@pytest.fixture
def RE() -> RunEngine:
    return RunEngine({})


@pytest.fixture
def devices(RE: RunEngine, tmp_path: Path) -> Iterator[RigDevices]:
    """The simulated rig's devices, connected; the simulators stopped afterwards."""
    with simulated_devices(StaticPathProvider(StaticFilenameProvider("frames"), tmp_path),
                           seed=3) as devs:
        RE(ensure_connected(*devs))
        yield devs


def _cause(info: pytest.ExceptionInfo) -> BaseException:
    """The exception a failed status carries (FailedStatus wraps it)."""
    exc = info.value
    while exc.__cause__ is not None:
        exc = exc.__cause__
    return exc


def _read(RE: RunEngine, device) -> dict:
    return {k: v["value"] for k, v in call_in_bluesky_event_loop(device.read()).items()}


def test_the_turntable_reads_back_the_angles_it_was_sent_to(RE, devices):
    tt = devices.turntable
    for target in (42.5, -17.25, 0.0):
        RE(bps.mv(tt, target))
        reading = _read(RE, tt)
        assert reading["turntable"] == pytest.approx(target, abs=0.01)
        assert reading["turntable-setpoint"] == pytest.approx(target, abs=1e-9)
        # the driver and the simulated controller agree with the device
        assert devices.rig.turntable.position_deg() == pytest.approx(reading["turntable"])
        model = devices.rig.sims["turntable"].models["turntable"]
        assert model.current_position() == pytest.approx(target, abs=0.01)
    location = call_in_bluesky_event_loop(tt.locate())
    assert location["setpoint"] == pytest.approx(0.0) and location["readback"] == pytest.approx(
        0.0, abs=0.01)


def test_the_turntable_limits_are_the_controllers_and_a_target_outside_is_refused(RE, devices):
    tt = devices.turntable
    config = {k: v["value"] for k, v in
              call_in_bluesky_event_loop(tt.read_configuration()).items()}
    assert (config["turntable-low_limit"], config["turntable-high_limit"]) == (-170.0, 170.0)
    assert devices.rig.turntable.limits_deg == (-170.0, 170.0)
    RE(bps.mv(tt, 10.0))
    with pytest.raises(FailedStatus) as info:
        RE(bps.mv(tt, 200.0))
    error = _cause(info)
    assert isinstance(error, LimitError) and isinstance(error, ValueError)
    text = str(error)
    assert "turntable" in text and "200 deg" in text and "[-170, 170] deg" in text, text
    assert devices.rig.turntable.position_deg() == pytest.approx(10.0, abs=0.01)  # not moved
    # the device checks a target without moving, as Bluesky's check_limits asks it to
    with pytest.raises(LimitError, match=r"-171 deg is outside the allowed range"):
        call_in_bluesky_event_loop(tt.check_value(-171.0))
    with pytest.raises(LimitError):
        check_limits(bp.scan([devices.camera], tt, -180, 180, 3))
    check_limits(bp.scan([devices.camera], tt, -60, 60, 5))  # within: passes


def test_the_solar_level_lights_sets_and_puts_out_the_lamp(RE, devices):
    solar = devices.solar
    RE(bps.mv(solar, 1.1, solar.shutter, True))
    reading = _read(RE, solar)
    assert reading["solar"] == pytest.approx(1.1, abs=0.02)
    assert reading["solar-setpoint"] == 1.1
    assert reading["solar-lamp"] is True and reading["solar-shutter"] is True
    state = devices.rig.state()  # the rig reads the same devices
    assert state.shutter_open and state.solar_suns == pytest.approx(1.1, abs=0.02)
    RE(bps.mv(solar, 0.85))
    assert _read(RE, solar)["solar"] == pytest.approx(0.85, abs=0.02)
    RE(bps.mv(solar, 0.0, solar.shutter, False))
    reading = _read(RE, solar)
    assert reading["solar"] == 0.0 and reading["solar-lamp"] is False
    assert reading["solar-shutter"] is False
    assert not devices.rig.solar.is_lamp_on()


def test_a_level_outside_the_solar_simulators_range_is_refused(RE, devices):
    for level in (1.5, 0.5, -1.0):
        with pytest.raises(FailedStatus) as info:
            RE(bps.mv(devices.solar, level))
        error = _cause(info)
        assert isinstance(error, LimitError), error
        assert f"{level:g} sun" in str(error) and "[0.8, 1.2] sun" in str(error)
        assert "0 puts the lamp out" in str(error)
    assert not devices.rig.solar.is_lamp_on()  # nothing was lit


def test_a_lamp_that_went_out_behind_the_devices_back_is_not_relit_by_a_level(RE, devices):
    solar = devices.solar
    RE(bps.mv(solar, 1.0))
    devices.rig.solar.lamp_off()  # out, and not through the device: as if it went out
    with pytest.raises(FailedStatus) as info:
        RE(bps.mv(solar, 1.0))
    error = _cause(info)
    assert isinstance(error, LampFaultError), error
    assert "went out by itself" in str(error) and "solar.lamp" in str(error)
    assert not devices.rig.solar.is_lamp_on()
    RE(bps.mv(solar.lamp, True))  # the operator's relight
    RE(bps.mv(solar, 1.0))
    assert _read(RE, solar)["solar"] == pytest.approx(1.0, abs=0.02)


def test_a_count_writes_each_frame_with_the_rig_state_it_was_captured_in(RE, devices,
                                                                          tmp_path):
    captured = []
    devices.camera.writer.on_frame = lambda i, raw, frame: captured.append((i, raw))
    RE(bps.mv(devices.turntable, 25.0, devices.solar, 1.0, devices.solar.shutter, True))
    docs = []
    RE(bp.count([devices.camera], num=3), lambda name, doc: docs.append((name, doc)))
    assert [i for i, _ in captured] == [0, 1, 2]
    with h5py.File(tmp_path / "frames.h5", "r") as f:
        assert f["/entry/raw/data"].shape == (3, 1, 4, 171, 224)
        for i, raw in captured:
            np.testing.assert_array_equal(f["/entry/raw/data"][i], raw.phase_images)
        np.testing.assert_allclose(f["/entry/rig/turntable_angle_deg"][()], 25.0, atol=0.01)
        np.testing.assert_allclose(f["/entry/rig/solar_suns"][()], 1.0, atol=0.02)
    stop = docs[-1][1]
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 3}


def test_a_second_run_never_writes_over_the_first_run_s_file(RE, devices, tmp_path):
    """With one file name for every run, the second run is refused naming the file and the
    first run's frames stay as they were; with a name per run, each run's documents point
    into a file of its own."""
    RE(bp.count([devices.camera], num=2))
    first = (tmp_path / "frames.h5").read_bytes()
    with pytest.raises(FailedStatus) as info:
        RE(bp.count([devices.camera], num=1))
    error = _cause(info)
    assert isinstance(error, FileExistsError), error
    assert "frames.h5 exists" in str(error) and "AutoIncrementFilenameProvider" in str(error)
    assert (tmp_path / "frames.h5").read_bytes() == first

    from ophyd_async.core import AutoIncrementFilenameProvider

    with simulated_devices(StaticPathProvider(AutoIncrementFilenameProvider("run"),
                                              tmp_path / "runs"), seed=4) as devs:
        RE(ensure_connected(*devs))
        uris = []
        for n in (2, 3):
            docs: list = []
            RE(bp.count([devs.camera], num=n), lambda name, doc, docs=docs: docs.append(
                (name, doc)))
            resources = [d for name, d in docs if name == "stream_resource"]
            uris.append({r["uri"] for r in resources})
            datums = [d for name, d in docs if name == "stream_datum"
                      and d["stream_resource"] == resources[0]["uid"]]
            assert [d["indices"]["start"] for d in datums] == list(range(n))
            path = Path(next(iter(uris[-1])).removeprefix("file://localhost"))
            with h5py.File(path, "r") as f:
                assert f["/entry/depth/data"].shape[0] == n
        assert len(uris[0] | uris[1]) == 2  # two files


def test_two_kickoffs_of_one_prepare_capture_the_prepared_frames_only(RE, devices, tmp_path):
    """A fly scan prepared for 4 frames and kicked off twice for 2 each writes 4 frames, not
    a new loop of 4 per kickoff."""
    from ophyd_async.core import TriggerInfo

    cam = devices.camera

    def fly():
        yield from bps.open_run()
        yield from bps.stage(cam)
        yield from bps.prepare(cam, TriggerInfo(number_of_events=4), wait=True)
        yield from bps.declare_stream(cam, name="primary")
        for _ in range(2):
            yield from bps.mv(cam.events_to_kickoff, 2)
            yield from bps.kickoff(cam, wait=True)
            yield from bps.complete(cam, wait=True)
            yield from bps.collect(cam)
        yield from bps.unstage(cam)
        yield from bps.close_run()

    docs = []
    RE(fly(), lambda name, doc: docs.append((name, doc)))
    with h5py.File(tmp_path / "frames.h5", "r") as f:
        assert f["/entry/depth/data"].shape[0] == 4
    depth = next(d for name, d in docs if name == "stream_resource"
                 and d["data_key"].endswith("-depth"))
    seq = [d["seq_nums"] for name, d in docs if name == "stream_datum"
           and d["stream_resource"] == depth["uid"]]
    assert seq and seq[0]["start"] == 1 and seq[-1]["stop"] == 5, seq


def test_a_capture_that_fails_fails_the_plan_with_the_drivers_error(RE, tmp_path):
    rig = simulated_rig(camera_faults=["no-data"],
                        camera_settings=UsbCameraSettings(read_timeout_s=0.2,
                                                          no_data_retries=0))
    with rig_devices(rig, StaticPathProvider(StaticFilenameProvider("frames"),
                                             tmp_path)) as devs:
        RE(ensure_connected(*devs))
        docs = []
        t0 = time.monotonic()
        with pytest.raises(FailedStatus) as info:
            RE(bp.count([devs.camera]), lambda name, doc: docs.append((name, doc)))
        # the driver's own timeout, at once: not ophyd-async's wait for a frame that never
        # comes (10 s)
        assert isinstance(_cause(info), DeviceTimeoutError), _cause(info)
        assert time.monotonic() - t0 < 8.0
    assert docs[-1][0] == "stop" and docs[-1][1]["exit_status"] == "fail"
