"""The pyusb camera driver against the simulated pico flexx, through pyusb's normal code path."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from drivers.camera import (
    CameraAccessError,
    CameraError,
    CameraNotFoundError,
    CameraProtocol,
    UsbCamera,
    UsbCameraSettings,
)
from drivers.camera.wire import (
    USE_CASES,
    Request,
    RequestType,
    quantize_frame,
)
from drivers.errors import DeviceInputError
from drivers.sim.usb_camera import CameraRequest, UsbCameraSim, plane_source
from sim_core.raw import reconstruct_raw

pytestmark = pytest.mark.timeout(20)

FAST = UsbCameraSettings(read_timeout_s=0.2, reconnect_timeout_s=1.0)
SEED = 11


@pytest.fixture
def sim():
    return UsbCameraSim(plane_source(1.5, amplitude_dn=500.0, noise_dn=4.0), seed=SEED)


@pytest.fixture
def camera(sim):
    with UsbCamera(backend=sim, settings=FAST) as cam:
        yield cam


def _source_frame(sim, frame):
    """The simulator's source frame for a captured frame, quantised as the wire does."""
    uc = USE_CASES[frame.meta["use_case"]]
    request = CameraRequest(uc, frame.meta["sequence"], SEED)
    return quantize_frame(sim.device.frame_source(request), uc)


def _assert_same_arrays(frame, expected):
    for name in ("phase_images", "intensity", "saturated", "sbi_limit", "frequencies_hz"):
        assert np.array_equal(getattr(frame, name), getattr(expected, name)), name
    assert frame.exposure_s == expected.exposure_s


def test_capture_of_n_frames_has_the_pico_flexx_shape_and_dtype(camera):
    frames = camera.capture(5)
    assert len(frames) == 5
    for frame in frames:
        assert frame.phase_images.shape == (1, 4, 171, 224)
        assert frame.phase_images.dtype == np.float32
        assert frame.intensity.shape == (171, 224) and frame.intensity.dtype == np.float32
        assert frame.saturated.dtype == bool and frame.sbi_limit.dtype == bool
        assert frame.frequencies_hz.tolist() == [60.24e6]
        assert frame.exposure_s == pytest.approx(500e-6)
        assert frame.meta["backend"] == "pyusb"
    assert [f.meta["sequence"] for f in frames] == [0, 1, 2, 3, 4]
    stamps = [f.timestamp_s for f in frames]
    assert stamps == sorted(stamps) and abs(stamps[0] - time.time()) < 60
    assert camera.stats.frames == 5 and camera.stats.dropped == 0


@pytest.mark.parametrize("use_case", sorted(USE_CASES))
def test_driver_frame_equals_source_frame_after_12_bit_quantisation(sim, camera, use_case):
    camera.configure(use_case)
    for frame in camera.capture(3):
        _assert_same_arrays(frame, _source_frame(sim, frame))


def test_two_frequency_frames_reconstruct_the_plane_distance(camera):
    camera.configure("MODE_9_5FPS_2000")
    frame = camera.capture(1)[0]
    assert frame.frequencies_hz.tolist() == [80.32e6, 60.24e6]
    image = reconstruct_raw(frame, np.ones((171, 224)))
    assert image.valid.all()
    assert np.nanmedian(image.range_m) == pytest.approx(1.5, abs=0.01)


def test_reads_of_single_packets_reassemble_the_same_frames(sim):
    settings = dataclasses.replace(FAST, chunk_bytes=512)
    with UsbCamera(backend=sim, settings=settings) as cam:
        frames = cam.capture(2)
    for frame in frames:
        _assert_same_arrays(frame, _source_frame(sim, frame))


def test_read_size_is_rounded_up_to_whole_packets(sim):
    settings = dataclasses.replace(FAST, chunk_bytes=1000)  # 1024 = 2 packets of 512
    with UsbCamera(backend=sim, settings=settings) as cam:
        assert len(cam.capture(2)) == 2


def test_frames_ending_on_a_packet_boundary_end_with_a_zero_length_packet():
    # 383104 bytes = 5986 packets of 64: the transfer ends with a ZLP
    sim = UsbCameraSim(plane_source(), seed=SEED, max_packet_size=64)
    settings = dataclasses.replace(FAST, chunk_bytes=383_104)
    with UsbCamera(backend=sim, settings=settings) as cam:
        frames = cam.capture(3)
    assert [f.meta["sequence"] for f in frames] == [0, 1, 2]
    for frame in frames:
        _assert_same_arrays(frame, _source_frame(sim, frame))


def test_connect_configures_the_use_case_with_a_vendor_request(sim):
    with UsbCamera(backend=sim, use_case="MODE_9_5FPS_2000", settings=FAST) as cam:
        assert cam.use_case.name == "MODE_9_5FPS_2000"
        vendor = [t for t in sim.device.transcript if t[0] == RequestType.OUT]
        assert vendor == [(RequestType.OUT, Request.SET_USE_CASE, 2, 0)]
        assert sim.device.use_case.name == "MODE_9_5FPS_2000"


def test_configure_while_streaming_stops_reconfigures_and_restarts(sim, camera):
    camera.start()
    sim.device.transcript.clear()
    camera.configure("MODE_9_5FPS_2000")
    vendor = [t[1:3] for t in sim.device.transcript if t[0] == RequestType.OUT]
    assert vendor == [(Request.STOP, 0), (Request.SET_USE_CASE, 2), (Request.START, 0)]
    assert camera.is_streaming and sim.device.streaming
    assert camera.capture(1)[0].phase_images.shape == (2, 4, 171, 224)


def test_one_shot_capture_starts_and_stops_the_stream(sim, camera):
    camera.capture(1)
    assert not sim.device.streaming and not camera.is_streaming
    camera.start()
    camera.capture(2)
    assert sim.device.streaming and camera.is_streaming
    camera.stop()
    assert not sim.device.streaming


def test_paced_stream_delivers_frames_at_the_use_case_rate():
    sim = UsbCameraSim(plane_source(), seed=SEED, instant=False)
    with UsbCamera(backend=sim, settings=FAST) as cam:
        start = time.monotonic()
        frames = cam.capture(4)
        elapsed = time.monotonic() - start
    assert elapsed >= 3 / 45.0 * 0.99  # frame k is due k/45 s after START
    assert [f.meta["sequence"] for f in frames] == [0, 1, 2, 3]


def test_identity_comes_from_the_usb_descriptors(camera):
    ident = camera.identity()
    assert isinstance(camera, CameraProtocol)
    assert (ident.model, ident.serial, ident.product) == (
        "pico flexx",
        "0005-4804-0050-1827",
        "pico flexx (simulated)",
    )
    assert (ident.vendor_id, ident.product_id) == (0x1C28, 0xC012)
    assert ident.usb_speed == "high (480 Mbit/s)" and ident.firmware == "1.00"
    assert ident.backend == "pyusb" and ident.extra["wire_version"] == "2"


def test_unknown_use_case_is_refused_before_anything_is_sent(sim, camera):
    sim.device.transcript.clear()
    with pytest.raises(DeviceInputError, match=r"^use_case: got 'MODE_1_1FPS_1'"):
        camera.configure("MODE_1_1FPS_1")
    assert not sim.device.transcript


@pytest.mark.parametrize("n", [0, -1, 1.5, True])
def test_capture_needs_a_positive_integer(camera, n):
    with pytest.raises(DeviceInputError, match=r"^n: got"):
        camera.capture(n)


def test_serial_number_selects_the_device(sim):
    sim.add_device(serial="0005-0000-0000-0002", address=9)
    with UsbCamera("0005-0000-0000-0002", backend=sim, settings=FAST) as cam:
        assert cam.identity().address == 9
    with pytest.raises(CameraNotFoundError, match=r"no camera 1c28:c012 \(serial 'nope'\)"):
        UsbCamera("nope", backend=sim, settings=FAST).connect()


def test_permission_problem_names_the_udev_rule():
    sim = UsbCameraSim(access="denied")
    with pytest.raises(CameraAccessError, match="permission denied") as info:
        UsbCamera(backend=sim, settings=FAST).connect()
    assert 'ATTRS{idVendor}=="1c28", ATTRS{idProduct}=="c012"' in info.value.fix
    assert "udevadm" in str(info.value)


def test_interface_held_by_another_program_is_named():
    sim = UsbCameraSim(busy=True)
    with pytest.raises(CameraAccessError, match=r"interface busy.*close the other program"):
        UsbCamera(backend=sim, settings=FAST).connect()


def test_kernel_driver_is_detached_when_connecting():
    sim = UsbCameraSim(kernel_driver_active=True)
    with UsbCamera(backend=sim, settings=FAST) as cam:
        assert len(cam.capture(1)) == 1
    assert not sim.device.kernel_driver_active


def test_kernel_driver_left_attached_blocks_the_claim():
    sim = UsbCameraSim(kernel_driver_active=True)
    settings = dataclasses.replace(FAST, detach_kernel_driver=False)
    with pytest.raises(CameraAccessError, match="interface busy"):
        UsbCamera(backend=sim, settings=settings).connect()


def test_device_without_our_wire_protocol_is_recognised():
    sim = UsbCameraSim(speaks_wire=False)
    with pytest.raises(CameraError, match=r"does not speak the toftwin USB wire protocol.*royale"):
        UsbCamera(backend=sim, settings=FAST).connect()


def test_device_of_another_wire_version_is_refused(sim):
    real_status = sim.device.status
    sim.device.status = lambda: dataclasses.replace(real_status(), wire_version=3)
    with pytest.raises(CameraError, match="speaks wire version 3; this driver speaks 1, 2"):
        UsbCamera(backend=sim, settings=FAST).connect()


def test_close_stops_streaming_and_is_idempotent(sim):
    cam = UsbCamera(backend=sim, settings=FAST)
    cam.connect()
    cam.start()
    cam.close()
    cam.close()
    assert not sim.device.streaming and not sim.device.claimed
    assert not cam.is_connected


def test_settings_are_checked():
    with pytest.raises(DeviceInputError, match=r"^on_bad_frame: got 'ignore'"):
        UsbCameraSettings(on_bad_frame="ignore")
    with pytest.raises(DeviceInputError, match=r"^read_timeout_s: got 0"):
        UsbCameraSettings(read_timeout_s=0)
