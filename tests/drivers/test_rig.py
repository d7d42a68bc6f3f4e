"""The rig: three simulators, real drivers, one lock."""

from __future__ import annotations

import os
import threading
import time

import pytest

from drivers.camera import UsbCamera
from drivers.errors import DeviceInputError, DeviceTimeoutError, LimitError
from drivers.rig import Rig, RigState
from drivers.sim.usb_camera import CameraRequest, plane_source
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

    rig = Rig.simulated(recording, seed=4)
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
    with Rig.simulated(camera_faults=["drop:1@1"]) as rig:
        frames = rig.capture(3)
        assert [f.meta["sequence"] for f in frames] == [0, 2, 3]
        assert rig.camera.stats.dropped == 1


def test_close_tears_everything_down_and_is_idempotent():
    rig = Rig.simulated()
    ports = [*rig.sims["turntable"].ports, *rig.sims["solar"].ports]
    assert all(os.path.exists(p) for p in ports)
    rig.close()
    rig.close()
    assert not any(os.path.exists(p) for p in ports)
    assert not rig.camera.is_connected and not rig.sims["camera"].device.claimed
