"""The rig: three simulators, real drivers, one lock."""

from __future__ import annotations

import dataclasses
import os
import re
import threading
import time

import pytest

from drivers.camera import CameraNotFoundError, UsbCamera
from drivers.errors import (
    DeviceDisconnectedError,
    DeviceInputError,
    DeviceTimeoutError,
    InterlockError,
    LampFaultError,
    LimitError,
    SolarSimulatorError,
    TurntableError,
)
from drivers.rig import Rig, RigState
from drivers.sim.rig import simulated_rig
from drivers.sim.usb_camera import CameraRequest, UsbCameraSim, plane_source
from drivers.solar_simulator import SolarSimulator
from drivers.turntable import Turntable

pytestmark = pytest.mark.timeout(20)


@pytest.fixture
def requests_seen() -> list[CameraRequest]:
    return []


@pytest.fixture
def rig(requests_seen):
    source = plane_source(1.0)

    def recording(request: CameraRequest):
        requests_seen.append(request)
        return source(request)

    rig = simulated_rig(recording, seed=4)
    yield rig
    rig.close()


def test_simulated_rig_has_real_drivers_on_the_three_simulators(rig):
    assert isinstance(rig.turntable, Turntable) and isinstance(rig.solar, SolarSimulator)
    assert isinstance(rig.camera, UsbCamera)
    assert rig.camera.identity().product == "pico flexx (simulated)"
    assert os.path.exists(rig.sims["turntable"].ports[0])
    state = rig.state()
    smc = rig.sims["turntable"].models["turntable"]
    assert state.turntable_angle_deg == pytest.approx(smc.current_position())
    assert (state.solar_suns, state.shutter_open) == (0.0, False)


def test_apply_drives_every_device_and_reads_the_state_back(rig):
    state = rig.apply(RigState(25.0, 1.1, True))
    assert state.turntable_angle_deg == pytest.approx(25.0, abs=0.01)
    assert state.solar_suns == pytest.approx(1.1, abs=0.01)
    assert state.shutter_open and state.irradiance_suns == pytest.approx(1.1, abs=0.01)
    assert rig.sims["solar"].models["rig"].irradiance_suns() == pytest.approx(1.1, abs=0.01)
    dark = rig.apply(RigState(-10.0, 0.0, False))
    assert dark.solar_suns == 0.0 and not dark.shutter_open
    assert not rig.solar.is_lamp_on()


def test_capture_records_the_rig_state_and_the_source_sees_the_physical_state(rig, requests_seen):
    rig.apply(RigState(40.0, 1.0, True))
    frames = rig.capture(2)
    assert len(frames) == 2 and frames[0].phase_images.shape == (1, 4, 171, 224)
    assert frames[0].meta["rig"]["turntable_angle_deg"] == pytest.approx(40.0, abs=0.01)
    assert frames[0].meta["rig"]["shutter_open"] is True
    seen = requests_seen[-1].rig_state
    assert isinstance(seen, RigState)
    assert seen.turntable_angle_deg == pytest.approx(40.0, abs=0.01)
    assert seen.solar_suns == pytest.approx(1.0, abs=0.01) and seen.shutter_open
    assert requests_seen[-1].seed == 4


def test_hold_excludes_other_threads_and_names_the_holder(rig):
    errors: list[Exception] = []

    def other() -> None:
        try:
            with rig.hold(timeout_s=0.1):
                pass
        except DeviceTimeoutError as exc:
            errors.append(exc)

    with rig.hold():
        assert rig.is_held
        rig.state()  # rig methods work inside hold()
        with rig.hold():  # nested in the same thread: passes through
            pass
        thread = threading.Thread(target=other)
        thread.start()
        thread.join(2.0)
    assert len(errors) == 1 and "rig busy: its lock is held by thread" in str(errors[0])
    assert not rig.is_held


def test_sequences_of_two_threads_do_not_interleave(rig):
    log: list[str] = []

    def sequence(name: str, angle: float) -> None:
        with rig.hold():
            log.append(f"{name} start")
            rig.apply(RigState(angle, 0.0, False))
            time.sleep(0.02)
            log.append(f"{name} end")

    threads = [threading.Thread(target=sequence, args=(n, a)) for n, a in (("a", 5), ("b", 6))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert log in (
        ["a start", "a end", "b start", "b end"],
        ["b start", "b end", "a start", "a end"],
    )


def test_lock_is_released_when_the_block_raises(rig):
    with pytest.raises(LimitError, match=r"^suns: requested 1\.5 suns"), rig.hold():
        rig.apply(RigState(0.0, 1.5, False))
    assert not rig.is_held
    with rig.hold(timeout_s=0.1):
        pass


def test_rig_state_checks_its_fields():
    with pytest.raises(DeviceInputError, match=r"^solar_suns: got -1"):
        RigState(0.0, -1.0, False)
    with pytest.raises(DeviceInputError, match=r"^turntable_angle_deg: got nan"):
        RigState(float("nan"), 1.0, False)


def test_camera_faults_reach_the_rig_camera():
    with simulated_rig(camera_faults=["drop:1@1"]) as rig:
        frames = rig.capture(3)
        assert [f.meta["sequence"] for f in frames] == [0, 2, 3]
        assert rig.camera.stats.dropped == 1


def test_close_tears_everything_down_and_is_idempotent():
    rig = simulated_rig()
    ports = [*rig.sims["turntable"].ports, *rig.sims["solar"].ports]
    assert all(os.path.exists(p) for p in ports)
    rig.close()
    rig.close()
    assert not any(os.path.exists(p) for p in ports)
    assert not rig.camera.is_connected and not rig.sims["camera"].device.claimed


# -- Rig.open: the real rig, here on the serial simulators and the simulated USB camera ------
def _fds_on(port: str) -> int:
    """How many file descriptors of this process are open on the device behind ``port``."""
    target = os.path.realpath(port)
    fds = os.listdir("/proc/self/fd")
    return sum(os.path.realpath(f"/proc/self/fd/{fd}") == target for fd in fds)


@pytest.fixture
def camera_sim() -> UsbCameraSim:
    return UsbCameraSim(plane_source(1.0), seed=2, serial="0005-RIG-OPEN")


needs_proc = pytest.mark.skipif(
    not os.path.isdir("/proc/self/fd"), reason="counts open descriptors in /proc"
)


@needs_proc
def test_open_connects_the_real_drivers_and_close_releases_them(
    turntable_sim, solar_sim, camera_sim
):
    ports = [turntable_sim.ports[0], *solar_sim.ports]
    before = [_fds_on(p) for p in ports]
    rig = Rig.open(
        *ports, turntable_address=1, camera_serial="0005-RIG-OPEN", usb_backend=camera_sim
    )
    with rig:
        assert isinstance(rig.turntable, Turntable) and isinstance(rig.solar, SolarSimulator)
        assert isinstance(rig.camera, UsbCamera)
        assert rig.camera.identity().serial == "0005-RIG-OPEN"
        assert [_fds_on(p) for p in ports] == [n + 1 for n in before]
        assert rig.sims == {}
        state = rig.apply(RigState(15.0, 0.0, True))
        assert state.turntable_angle_deg == pytest.approx(15.0, abs=0.01) and state.shutter_open
        assert turntable_sim.models["turntable"].current_position() == pytest.approx(15.0, abs=0.01)
        frames = rig.capture(1)
        assert frames[0].meta["rig"]["turntable_angle_deg"] == pytest.approx(15.0, abs=0.01)
    assert [_fds_on(p) for p in ports] == before
    assert not rig.camera.is_connected and not camera_sim.device.claimed


@needs_proc
def test_open_with_a_bad_lamp_port_closes_the_turntable_and_raises(
    turntable_sim, solar_sim, camera_sim, tmp_path
):
    port = turntable_sim.ports[0]
    before = _fds_on(port)
    bad = str(tmp_path / "no-such-lamp-port")
    refused = r"^cannot open port '.*no-such-lamp-port'"
    with pytest.raises(DeviceDisconnectedError, match=refused) as exc:
        Rig.open(port, bad, solar_sim.ports[1], usb_backend=camera_sim)
    # closed by Rig.open, not by the garbage collector: the traceback keeps its locals alive
    assert "turntable" in exc.tb.tb_next.tb_frame.f_locals
    assert _fds_on(port) == before
    assert not camera_sim.device.claimed


@needs_proc
def test_open_without_the_camera_closes_the_serial_devices_and_raises(
    turntable_sim, solar_sim, camera_sim
):
    ports = [turntable_sim.ports[0], *solar_sim.ports]
    before = [_fds_on(p) for p in ports]
    with pytest.raises(CameraNotFoundError, match=r"serial 'no-such-serial'") as exc:
        Rig.open(*ports, camera_serial="no-such-serial", usb_backend=camera_sim)
    assert {"turntable", "solar"} <= set(exc.tb.tb_next.tb_frame.f_locals)
    assert [_fds_on(p) for p in ports] == before


# -- what apply reads back is checked against what it asked for --------------------------------
@pytest.mark.parametrize("skip", range(8))
def test_apply_never_returns_a_state_the_lamp_did_not_reach(rig, skip):
    """The arc dies at any one of the lamp supply's commands during apply: a device error."""
    rig.apply(RigState(10.0, 1.0, True))
    rig.sims["solar"].servers["lamp"].faults.inject(f"lamp-fault:1@{skip}")
    try:
        state = rig.apply(RigState(20.0, 1.0, True))
    except SolarSimulatorError as exc:
        assert "fault" in str(exc) or "out" in str(exc)
        return
    # the fault fired before the lamp was lit for this pose (it was relit), or after apply
    # read the state back: what apply returned was verified
    assert state.solar_suns == pytest.approx(1.0, abs=0.02)


def test_a_lamp_fault_after_the_last_lamp_command_is_caught_by_the_read_back(requests_seen):
    """Fault points after the level is set are seen only by comparing the read-back."""
    messages = []
    for skip in range(8):
        with simulated_rig(plane_source(1.0), seed=4) as rig:
            rig.apply(RigState(10.0, 1.0, True))
            rig.sims["solar"].servers["lamp"].faults.inject(f"lamp-fault:1@{skip}")
            try:
                rig.apply(RigState(20.0, 1.0, True))
            except SolarSimulatorError as exc:
                messages.append(str(exc))
    assert any("relight the lamp" in m for m in messages), messages


def test_a_lamp_that_went_out_is_not_relit_by_the_next_apply(rig):
    """The operator is told and relights it; a pose never does so silently."""
    rig.apply(RigState(10.0, 1.0, True))
    rig.sims["solar"].models["lamp"].lamp_on = False  # the arc dies between two poses
    with pytest.raises(LampFaultError, match=r"^solar simulator lamp: went out by itself .*"
                       r"does not relight it: relight the lamp"):
        rig.apply(RigState(20.0, 1.0, True))
    assert not rig.sims["solar"].models["lamp"].lamp_on
    rig.switch_lamp(True)  # the operator relights it (POST /api/v1/devices/solar/lamp)
    assert rig.apply(RigState(20.0, 1.0, True)).solar_suns == pytest.approx(1.0, abs=0.02)


def test_a_lamp_put_out_on_purpose_is_lit_by_the_next_pose(rig):
    rig.apply(RigState(10.0, 1.0, True))
    rig.apply(RigState(10.0, 0.0, False))  # a dark pose puts it out
    assert rig.apply(RigState(20.0, 1.0, True)).solar_suns == pytest.approx(1.0, abs=0.02)
    rig.switch_lamp(False)  # the operator puts it out
    assert rig.apply(RigState(20.0, 1.0, True)).solar_suns == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("skip", range(6))
def test_capture_with_a_target_refuses_a_lamp_that_went_out_around_the_exposure(
    rig, requests_seen, skip
):
    """The lamp goes out at any lamp command of a capture: before the exposure (the frame is
    exposed in the dark) or after it (unknown when): a device error naming the lamp, target and
    read-back, never frames."""
    target = RigState(20.0, 1.0, True)
    rig.apply(target)
    rig.sims["solar"].servers["lamp"].faults.inject(f"lamp-fault:1@{skip}")
    try:
        frames = rig.capture(1, target=target)
    except LampFaultError as exc:
        assert re.search(r"^solar simulator lamp: lamp (fault|out) (before|after) the exposure: "
                         r"target 1 sun, read back 0\.000 sun", str(exc)), str(exc)
        assert (exc.device, exc.target, exc.read_back) == ("solar simulator lamp", "1 sun",
                                                           "0.000 sun")
        return
    exposed = requests_seen[-1].rig_state  # what the simulated camera really exposed
    assert exposed.solar_suns == pytest.approx(1.0, abs=0.02)
    assert frames[0].meta["rig"]["solar_suns"] == pytest.approx(1.0, abs=0.02)
    assert frames[0].meta["rig_after"]["solar_suns"] == pytest.approx(1.0, abs=0.02)
    assert skip >= 4  # the capture's own lamp commands (two reads, two checks) came first


def test_capture_checks_the_rig_state_a_camera_puts_in_its_frames(rig):
    """A camera that reports the rig state in a frame's metadata is held to the target too."""
    target = RigState(20.0, 1.0, True)
    rig.apply(target)
    camera_capture = rig.camera.capture

    def reporting(n):
        return [dataclasses.replace(f, meta={**f.meta, "rig": {
            "turntable_angle_deg": 20.0, "solar_suns": 0.0, "shutter_open": True}})
            for f in camera_capture(n)]

    rig.camera.capture = reporting
    with pytest.raises(SolarSimulatorError, match=r"read back 0\.000 sun in the camera's frame "
                       r"metadata: target 1 sun") as info:
        rig.capture(1, target=target)
    assert (info.value.device, info.value.read_back) == ("solar simulator lamp", "0.000 sun")


def test_the_interlock_is_named_wherever_it_puts_the_lamp_out(rig):
    """The interlock opens for one command at each lamp command of apply (lighting, setting
    the level, waiting for stability, reading back): every error names it."""
    target = RigState(20.0, 1.0, True)
    lamp = rig.sims["solar"].servers["lamp"].faults
    named = 0
    for skip in range(20):
        lamp.clear()
        rig.apply(RigState(20.0, 0.0, False))  # a dark pose: the lamp out on purpose
        lamp.inject(f"interlock:1@{skip}")
        try:
            rig.apply(target, wait_stable_s=2.0)
        except SolarSimulatorError as exc:
            assert isinstance(exc, InterlockError) and "interlock" in str(exc), (skip, str(exc))
            named += 1
    assert named >= 10


@pytest.mark.parametrize(
    ("read_back", "error", "words"),
    [
        (RigState(20.05, 1.0, True), TurntableError, "turntable read back 20.0500 deg"),
        (RigState(20.0, 0.9, True), SolarSimulatorError, "solar level read back 0.900 sun"),
        (RigState(20.0, 1.0, False), SolarSimulatorError, "shutter not open"),
    ],
)
def test_verify_names_what_the_rig_did_not_reach(rig, read_back, error, words):
    rig.apply(RigState(20.0, 1.0, True))  # the lamp burns, so only the compared value differs
    with pytest.raises(error, match=words):
        rig.verify(RigState(20.0, 1.0, True), read_back)
    rig.verify(RigState(20.0, 1.0, True), RigState(20.004, 1.01, True))  # within tolerance


def test_verify_refuses_a_lamp_still_burning_after_it_was_put_out(rig):
    with pytest.raises(SolarSimulatorError, match="still burning"):
        rig.verify(RigState(0.0, 0.0, False), RigState(0.0, 0.95, False))
