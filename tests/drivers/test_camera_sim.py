"""The simulated pico flexx as a pyusb backend: descriptors, requests, packets, unplugging."""

from __future__ import annotations

import errno
import time

import pytest
import usb.core
import usb.util

from drivers.camera.wire import (
    Request,
    RequestType,
    decode_frame,
    decode_status,
)
from drivers.errors import DeviceInputError
from drivers.sim.usb_camera import (
    CAMERA_FAULTS,
    CameraFaultInjector,
    CameraRequest,
    UsbCameraSim,
    parse_camera_fault,
    plane_source,
)
from tests.drivers.helpers import MODE5

pytestmark = pytest.mark.timeout(10)


@pytest.fixture
def sim():
    return UsbCameraSim(plane_source(), seed=2)


@pytest.fixture
def dev(sim):
    device = usb.core.find(backend=sim, idVendor=0x1C28, idProduct=0xC012)
    assert device is not None
    yield device
    usb.util.dispose_resources(device)


def _status(dev):
    return decode_status(bytes(dev.ctrl_transfer(RequestType.IN, Request.GET_STATUS, 0, 0, 16)))


def _stall(call):
    with pytest.raises(usb.core.USBError) as info:
        call()
    assert info.value.errno == errno.EPIPE and info.value.backend_error_code == -9


# -- descriptors -----------------------------------------------------------------------------
def test_find_sees_the_device_descriptor_of_a_pico_flexx(dev):
    assert (dev.idVendor, dev.idProduct, dev.bcdUSB, dev.bcdDevice) == (
        0x1C28,
        0xC012,
        0x210,
        0x100,
    )
    assert (dev.bus, dev.address, dev.port_numbers, dev.speed) == (1, 4, (2,), usb.util.SPEED_HIGH)
    assert dev.bNumConfigurations == 1


def test_string_descriptors_are_served_over_get_descriptor(sim, dev):
    assert dev.langids == (0x0409,)
    assert dev.product == "pico flexx (simulated)"
    assert dev.serial_number == "0005-4804-0050-1827"
    assert dev.manufacturer == "pmdtechnologies ag (simulated)"
    assert (0x80, 0x06, 0x0302, 0x0409) in sim.device.transcript


def test_configuration_interface_and_bulk_in_endpoint(dev):
    cfg = dev.get_active_configuration()
    assert cfg.bConfigurationValue == 1 and cfg.bNumInterfaces == 1
    intf = cfg[(0, 0)]
    assert (intf.bInterfaceClass, intf.bNumEndpoints) == (0xFF, 1)
    ep = usb.util.find_descriptor(intf, bEndpointAddress=0x81)
    assert usb.util.endpoint_type(ep.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK
    assert usb.util.endpoint_direction(ep.bEndpointAddress) == usb.util.ENDPOINT_IN
    assert ep.wMaxPacketSize == 512
    assert "ENDPOINT 0x81: Bulk IN" in str(dev)  # pyusb's full descriptor dump works


def test_other_vendors_are_not_found_by_pmd_vendor_id(sim):
    sim.add_device(vendor_id=0x046D, product_id=0x0825, product="webcam", address=7)
    assert len(list(usb.core.find(find_all=True, backend=sim))) == 2
    assert len(list(usb.core.find(find_all=True, backend=sim, idVendor=0x1C28))) == 1


# -- vendor requests -------------------------------------------------------------------------
def test_get_status_after_power_on(dev):
    status = _status(dev)
    assert (status.wire_version, status.use_case_code, status.streaming) == (2, 0, False)
    assert (status.next_sequence, status.firmware) == (0, "1.00")


def test_set_use_case_and_start_are_reflected_in_the_status(dev):
    dev.ctrl_transfer(RequestType.OUT, Request.SET_USE_CASE, 2, 0)
    dev.ctrl_transfer(RequestType.OUT, Request.START, 0, 0)
    status = _status(dev)
    assert (status.use_case_code, status.streaming, status.width, status.height) == (
        2,
        True,
        224,
        171,
    )
    dev.ctrl_transfer(RequestType.OUT, Request.STOP, 0, 0)
    assert not _status(dev).streaming


@pytest.mark.parametrize(
    ("setup", "request_", "value", "error"),
    [
        ([], Request.SET_USE_CASE, 9, 2),  # unknown use case code
        ([], Request.START, 0, 4),  # no use case configured
        # busy streaming
        ([(Request.SET_USE_CASE, 1), (Request.START, 0)], Request.SET_USE_CASE, 2, 3),
        ([], 0x7F, 0, 1),  # unknown request
    ],
)
def test_refused_requests_stall_and_say_why_in_the_status(dev, setup, request_, value, error):
    for req, val in setup:
        dev.ctrl_transfer(RequestType.OUT, req, val, 0)
    _stall(lambda: dev.ctrl_transfer(RequestType.OUT, request_, value, 0))
    assert _status(dev).last_error == error


def test_a_device_without_our_protocol_stalls_vendor_requests():
    sim = UsbCameraSim(speaks_wire=False)
    dev = usb.core.find(backend=sim)
    _stall(lambda: dev.ctrl_transfer(RequestType.IN, Request.GET_STATUS, 0, 0, 16))


# -- the bulk stream -------------------------------------------------------------------------
def _start(dev, code=1):
    dev.ctrl_transfer(RequestType.OUT, Request.SET_USE_CASE, code, 0)
    dev.ctrl_transfer(RequestType.OUT, Request.START, 0, 0)


def test_bulk_in_times_out_while_not_streaming(dev):
    start = time.monotonic()
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, 512, 100)
    assert 0.09 <= time.monotonic() - start < 1.0


def test_a_frame_is_one_transfer_of_whole_packets_ended_by_a_short_packet(dev):
    _start(dev)
    sizes = []
    data = bytearray()
    while True:
        chunk = dev.read(0x81, 512 * 100, 500)
        sizes.append(len(chunk))
        data += chunk
        if len(chunk) < 512 * 100:
            break
    assert len(data) == MODE5.frame_bytes
    assert all(s == 51200 for s in sizes[:-1]) and sizes[-1] == MODE5.frame_bytes % 51200
    assert decode_frame(bytes(data)).header.sequence == 0
    # the next read starts the next frame
    assert dev.read(0x81, 512, 500).tobytes()[:4] == b"TOFW"


def test_a_read_that_is_not_whole_packets_overflows(dev):
    _start(dev)
    with pytest.raises(usb.core.USBError) as info:
        dev.read(0x81, 100, 500)
    assert info.value.errno == errno.EOVERFLOW


def test_stop_drops_the_frame_in_flight(sim, dev):
    _start(dev)
    dev.read(0x81, 512, 500)
    dev.ctrl_transfer(RequestType.OUT, Request.STOP, 0, 0)
    dev.ctrl_transfer(RequestType.OUT, Request.START, 0, 0)
    first = dev.read(0x81, 512, 500).tobytes()
    assert first[:4] == b"TOFW" and int.from_bytes(first[8:12], "little") == 1
    assert sim.device.frames_sent == 2


def test_frame_source_gets_use_case_index_seed_and_rig_state():
    seen: list[CameraRequest] = []
    source = plane_source()

    def recording(request: CameraRequest):
        seen.append(request)
        return source(request)

    sim = UsbCameraSim(recording, seed=99, state_provider=lambda: {"angle": 12.5})
    dev = usb.core.find(backend=sim)
    _start(dev, code=2)
    for _ in range(2):
        while len(dev.read(0x81, 65536, 500)) == 65536:
            pass
    assert [(r.use_case.name, r.frame_index, r.seed, r.rig_state) for r in seen] == [
        ("MODE_9_5FPS_2000", 0, 99, {"angle": 12.5}),
        ("MODE_9_5FPS_2000", 1, 99, {"angle": 12.5}),
    ]
    assert abs(seen[0].timestamp_s - time.time()) < 60


def test_same_seed_and_index_give_the_same_noise():
    src = plane_source(noise_dn=5.0)
    a = src(CameraRequest(MODE5, 3, seed=1)).phase_images
    b = src(CameraRequest(MODE5, 3, seed=1)).phase_images
    c = src(CameraRequest(MODE5, 4, seed=1)).phase_images
    assert (a == b).all() and not (a == c).all()


def test_a_source_returning_the_wrong_shape_is_named():
    sim = UsbCameraSim(lambda req: plane_source()(CameraRequest(MODE5, 0, 0)))
    dev = usb.core.find(backend=sim)
    _start(dev, code=2)  # the source ignores the two-frequency use case
    with pytest.raises(DeviceInputError, match=r"^frame_source: returned phase images \(1, 4"):
        dev.read(0x81, 512, 500)


# -- unplugging ------------------------------------------------------------------------------
def test_unplugged_device_vanishes_and_its_handle_dies(sim, dev):
    _status(dev)  # opens a handle
    sim.unplug(0.2)
    assert usb.core.find(backend=sim) is None
    with pytest.raises(usb.core.USBError) as info:
        _status(dev)
    assert info.value.errno == errno.ENODEV and info.value.backend_error_code == -4
    time.sleep(0.25)
    back = usb.core.find(backend=sim)
    assert back is not None and back.address == 5  # a new address, as after a real replug
    status = _status(back)
    assert (status.use_case_code, status.streaming, status.next_sequence) == (0, False, 0)
    with pytest.raises(usb.core.USBError):
        _status(dev)  # the old handle stays dead
    usb.util.dispose_resources(back)


def test_unplugged_for_good_until_plugged_in_again(sim):
    sim.unplug()
    time.sleep(0.05)
    assert usb.core.find(backend=sim) is None
    sim.plug()
    assert usb.core.find(backend=sim) is not None


def test_access_denied_on_open():
    sim = UsbCameraSim(access="denied")
    dev = usb.core.find(backend=sim)
    assert dev.idProduct == 0xC012  # enumeration needs no permission
    with pytest.raises(usb.core.USBError) as info:
        dev.is_kernel_driver_active(0)
    assert info.value.errno == errno.EACCES


# -- fault names -----------------------------------------------------------------------------
def test_every_required_camera_fault_has_a_name():
    assert set(CAMERA_FAULTS) == {"no-data", "truncated", "corrupt", "drop", "disconnect"}


@pytest.mark.parametrize(
    ("text", "name", "count", "skip"),
    [("drop", "drop", None, 0), ("corrupt:1", "corrupt", 1, 0), ("no-data:2@3", "no-data", 2, 3)],
)
def test_camera_fault_grammar(text, name, count, skip):
    fault = parse_camera_fault(text)
    assert (fault.name, fault.count, fault.skip) == (name, count, skip)


@pytest.mark.parametrize("text", ["smoke", "drop:0", "drop:", "DROP"])
def test_bad_camera_faults_are_refused(text):
    with pytest.raises(DeviceInputError, match="fault"):
        parse_camera_fault(text)


def test_fault_injector_counts_skip_then_count():
    injector = CameraFaultInjector(["drop:2@1"])
    assert [injector.fire("drop") is not None for _ in range(5)] == [
        False,
        True,
        True,
        False,
        False,
    ]
    assert injector.fired == ["drop", "drop"] and not injector.armed()
