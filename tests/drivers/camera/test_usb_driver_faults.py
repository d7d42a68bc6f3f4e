"""Every camera fault ends in a successful retry or a clear exception, never a hang.

Faults are injected in the simulated pico flexx (drivers.sim.usb_camera) and met by the real
driver (drivers.camera.UsbCamera) through pyusb. Every frame a capture returns despite a fault
must still equal the source frame after 12-bit quantisation: nothing damaged slips through.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from drivers.camera import FrameDroppedError, UsbCamera, UsbCameraSettings
from drivers.camera.wire import USE_CASES, CorruptFrameError, TruncatedFrameError, quantize_frame
from drivers.errors import DeviceDisconnectedError, DeviceTimeoutError
from drivers.sim.usb_camera import CameraRequest, UsbCameraSim, plane_source

SEED = 5
SKIP = UsbCameraSettings(read_timeout_s=0.1, no_data_retries=2, reconnect_timeout_s=1.0)
RAISE = dataclasses.replace(SKIP, on_bad_frame="raise")


def _camera(*faults: str, settings: UsbCameraSettings = SKIP) -> tuple[UsbCameraSim, UsbCamera]:
    sim = UsbCameraSim(plane_source(2.0, noise_dn=3.0), seed=SEED, faults=faults)
    cam = UsbCamera(backend=sim, settings=settings)
    cam.connect()
    return sim, cam


def _assert_intact(sim: UsbCameraSim, frames) -> None:
    for frame in frames:
        uc = USE_CASES[frame.meta["use_case"]]
        expected = quantize_frame(
            sim.device.frame_source(CameraRequest(uc, frame.meta["sequence"], SEED)), uc
        )
        assert np.array_equal(frame.phase_images, expected.phase_images)
        assert np.array_equal(frame.intensity, expected.intensity)


# -- no data -------------------------------------------------------------------------------
@pytest.mark.timeout(10)
def test_brief_silence_is_retried():
    sim, cam = _camera("no-data:2")
    frames = cam.capture(3)
    assert [f.meta["sequence"] for f in frames] == [0, 1, 2]
    assert cam.stats.timeouts == 2
    _assert_intact(sim, frames)
    cam.close()


@pytest.mark.timeout(10)
def test_no_data_at_all_raises_a_timeout_naming_the_endpoint():
    _, cam = _camera("no-data")
    start = time.monotonic()
    with pytest.raises(
        DeviceTimeoutError, match=r"no frame within 0\.1 s on bulk IN 0x81 \(3 reads"
    ):
        cam.capture(2)
    assert time.monotonic() - start < 2.0
    assert not cam.is_streaming  # the one-shot capture stopped the stream again
    cam.close()


# -- truncated and corrupt -----------------------------------------------------------------
@pytest.mark.timeout(10)
@pytest.mark.parametrize(
    ("fault", "n", "sequences", "counter"),
    [("truncated:1@1", 3, [0, 2, 3], "truncated"), ("corrupt:1@2", 4, [0, 1, 3, 4], "corrupt")],
)
def test_a_damaged_frame_is_skipped_and_counted(fault, n, sequences, counter):
    sim, cam = _camera(fault)
    frames = cam.capture(n)
    assert [f.meta["sequence"] for f in frames] == sequences
    assert (getattr(cam.stats, counter), cam.stats.dropped) == (1, 0)  # damaged, not missing
    _assert_intact(sim, frames)
    cam.close()


@pytest.mark.timeout(10)
def test_truncated_frame_raises_when_asked_to():
    _, cam = _camera("truncated:1", settings=RAISE)
    with pytest.raises(TruncatedFrameError, match=r"frame 0 truncated: 191552 of 383104") as info:
        cam.capture(1)
    assert info.value.reason == "truncated"
    assert len(cam.capture(1)) == 1  # the stream goes on
    cam.close()


@pytest.mark.timeout(10)
def test_corrupt_frame_raises_when_asked_to():
    _, cam = _camera("corrupt:1", settings=RAISE)
    with pytest.raises(CorruptFrameError, match="frame 0: payload CRC32") as info:
        cam.capture(1)
    assert info.value.reason == "payload-crc"
    cam.close()


@pytest.mark.timeout(10)
def test_a_stream_of_only_corrupt_frames_gives_up():
    _, cam = _camera("corrupt", settings=dataclasses.replace(SKIP, max_bad_frames=3))
    with pytest.raises(CorruptFrameError, match=r"gave up after 4 bad frames in a row"):
        cam.capture(1)
    assert cam.stats.corrupt == 4
    cam.close()


# -- dropped -------------------------------------------------------------------------------
@pytest.mark.timeout(10)
def test_dropped_frames_are_counted_from_the_sequence_gap():
    sim, cam = _camera("drop:2@1")
    frames = cam.capture(3)
    assert [f.meta["sequence"] for f in frames] == [0, 3, 4]
    assert cam.stats.dropped == 2 and cam.stats.frames == 3
    _assert_intact(sim, frames)
    cam.close()


@pytest.mark.timeout(10)
def test_dropped_frames_raise_when_asked_to():
    _, cam = _camera("drop:1@1", settings=RAISE)
    with pytest.raises(
        FrameDroppedError, match=r"1 frame dropped before frame 2 \(expected 1\)"
    ) as info:
        cam.capture(3)
    assert (info.value.missing, info.value.sequence, info.value.reason) == (1, 2, "dropped")
    cam.close()


# -- disconnect and reconnect ----------------------------------------------------------------
@pytest.mark.timeout(10)
def test_disconnect_mid_capture_reconnects_and_completes():
    sim, cam = _camera()
    sim.inject("disconnect:1@2", downtime_s=0.2)
    cam.start()
    frames = cam.capture(4)
    assert cam.stats.reconnects == 1
    # power-on after the replug: the device counts from 0 again, the driver starts afresh
    assert [f.meta["sequence"] for f in frames] == [0, 1, 0, 1]
    assert cam.stats.dropped == 0
    assert sim.device.address == 5 and sim.device.use_case.name == "MODE_5_45FPS_500"
    assert cam.is_streaming and sim.device.streaming  # streaming restored
    _assert_intact(sim, frames)
    cam.close()


@pytest.mark.timeout(10)
def test_reconnect_restores_the_configured_use_case():
    sim, cam = _camera()
    cam.configure("MODE_9_5FPS_2000")
    sim.inject("disconnect:1", downtime_s=0.1)
    frames = cam.capture(2)
    assert all(f.phase_images.shape == (2, 4, 171, 224) for f in frames)
    assert sim.device.use_case.name == "MODE_9_5FPS_2000"
    cam.close()


@pytest.mark.timeout(10)
def test_unplugged_while_idle_reconnects_at_the_next_capture():
    sim, cam = _camera()
    cam.capture(1)
    sim.unplug(0.15)
    frames = cam.capture(2)
    assert len(frames) == 2 and cam.stats.reconnects == 1
    cam.close()


@pytest.mark.timeout(10)
def test_camera_gone_for_good_raises_disconnected_within_the_timeout():
    sim, cam = _camera(settings=dataclasses.replace(SKIP, reconnect_timeout_s=0.5))
    sim.inject("disconnect:1", downtime_s=float("inf"))
    start = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match=r"disconnected .* not back within 0\.5 s"):
        cam.capture(2)
    assert time.monotonic() - start < 3.0
    sim.plug()  # it comes back later: the next capture reconnects
    assert len(cam.capture(1)) == 1
    cam.close()


@pytest.mark.timeout(10)
def test_reconnect_waits_for_the_same_camera_not_another_one():
    sim = UsbCameraSim(plane_source(), seed=SEED, serial="FIRST", address=4)
    sim.add_device(plane_source(), seed=SEED, serial="SECOND", address=9)
    with UsbCamera(backend=sim, settings=SKIP) as cam:  # no serial given: the first found
        assert cam.identity().serial == "FIRST"
        sim.inject("disconnect:1", downtime_s=0.2)
        assert len(cam.capture(2)) == 2
        assert cam.identity().serial == "FIRST" and cam.stats.reconnects == 1
        assert not sim.devices[1].claimed
