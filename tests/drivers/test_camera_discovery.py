"""Discovery of PMD cameras on the USB bus and the device check the CLI runs."""

from __future__ import annotations

import json

import pytest
import usb.backend.libusb0
import usb.backend.libusb1
import usb.backend.openusb

from drivers.camera import UsbBackendError, discover, udev_rule
from drivers.devices_cli import DeviceCheck, DeviceReport, check_devices, list_devices
from drivers.sim.pty_server import start_simulator
from drivers.sim.usb_camera import UsbCameraSim

pytestmark = pytest.mark.timeout(20)

ROYALE_RULE = (
    'SUBSYSTEMS=="usb", ATTRS{idVendor}=="1c28", ATTRS{idProduct}=="c012", MODE="0666", '
    'SYMLINK+="camboard_pico_flexx-%k", GROUP="plugdev"'
)


@pytest.fixture
def bus():
    """A bus with four PMD cameras in different conditions and one webcam of another vendor."""
    sim = UsbCameraSim(serial="A-OK", address=4)
    sim.add_device(serial="B-DENIED", address=5, access="denied")
    sim.add_device(serial="C-KERNEL", address=6, kernel_driver_active=True)
    sim.add_device(serial="D-USB1", address=7, speed=2, usb_version=0x0110, bus=2)
    sim.add_device(vendor_id=0x046D, product_id=0x0825, product="webcam", address=8)
    return sim


def test_lists_pmd_cameras_with_serial_product_and_speed(bus):
    devices = list_devices(bus)
    assert [d["serial"] for d in devices] == ["A-OK", None, "C-KERNEL", "D-USB1"]
    ok = devices[0]
    assert ok["vendor_id"] == "1c28" and ok["product_id"] == "c012"
    assert ok["model"] == "pico flexx" and ok["product"] == "pico flexx (simulated)"
    assert ok["speed"] == "high (480 Mbit/s)" and ok["usb_version"] == "2.10"
    assert (ok["bus"], ok["address"], ok["port_path"]) == (1, 4, "1-2")
    assert ok["accessible"] and ok["problem"] is None and ok["kernel_driver_active"] is False
    assert devices[3]["speed"] == "full (12 Mbit/s)" and devices[3]["bus"] == 2
    json.dumps(devices)  # plain data for the CLI


def test_a_camera_without_permission_is_listed_with_the_udev_rule_to_add(bus):
    denied = list_devices(bus)[1]
    assert denied["accessible"] is False
    assert denied["problem"].startswith("permission denied opening the device")
    assert ROYALE_RULE in denied["fix"]
    assert "udevadm control --reload-rules" in denied["fix"]
    assert denied["product_id"] == "c012" and denied["address"] == 5  # still identified


def test_a_bound_kernel_driver_is_noted_with_the_fix(bus):
    kernel = list_devices(bus)[2]
    assert kernel["accessible"] and kernel["kernel_driver_active"] is True
    assert "kernel driver is bound to interface 0" in kernel["notes"][0]
    assert "detach_kernel_driver" in kernel["notes"][0]


def test_discovery_leaves_the_devices_closed(bus):
    discover(bus)
    assert all(not d.claimed for d in bus.devices)


def test_udev_rule_is_royales_line():
    assert udev_rule() == ROYALE_RULE


def test_no_libusb_is_reported_with_the_fix(monkeypatch):
    for module in (usb.backend.libusb1, usb.backend.openusb, usb.backend.libusb0):
        monkeypatch.setattr(module, "get_backend", lambda *a, **k: None)
    with pytest.raises(UsbBackendError, match=r"no backend .*apt-get install libusb-1\.0-0"):
        list_devices()


# -- check_devices -------------------------------------------------------------------------
@pytest.fixture
def serial_sims():
    with (
        start_simulator("turntable", instant=True) as turntable,
        start_simulator("solar-simulator", instant=True) as solar,
    ):
        yield turntable, solar


def test_check_of_a_healthy_simulated_rig(serial_sims):
    turntable, solar = serial_sims
    report = check_devices(
        usb_backend=UsbCameraSim(),
        probe_camera_wire=True,
        turntable_port=turntable.ports[0],
        lamp_port=solar.ports[0],
        shutter_port=solar.ports[1],
    )
    assert report.ok, str(report)
    camera = report.check("camera")
    assert camera.status == "ok"
    assert "pico flexx serial 0005-4804-0050-1827" in camera.detail
    assert "wire protocol v1, one MODE_5_45FPS_500 frame (1, 4, 171, 224) read" in camera.detail
    assert report.check("royale").status in ("ok", "warning")
    assert report.check("turntable").status == "warning"  # not referenced after power-on
    assert "NOT REFERENCED" in report.check("turntable").detail
    assert report.check("solar simulator").status == "ok"
    json.dumps(report.to_dict())
    assert str(report).splitlines()[0].startswith("[     ok] camera: pico flexx")


def test_check_reports_a_present_but_inaccessible_camera_with_the_fix():
    report = check_devices(usb_backend=UsbCameraSim(access="denied"))
    camera = report.check("camera")
    assert not report.ok and camera.status == "error"
    assert "present but not accessible: permission denied" in camera.detail
    assert ROYALE_RULE in camera.fix
    assert report.check("turntable").status == "skipped"
    assert report.check("solar simulator").status == "skipped"


def test_check_reports_a_missing_camera():
    sim = UsbCameraSim()
    sim.unplug()
    camera = check_devices(usb_backend=sim).check("camera")
    assert camera.status == "error" and "no pico flexx (1c28:c012) on the USB bus" in camera.detail
    assert "lsusb -d 1c28:" in camera.fix


def test_check_turns_driver_errors_into_error_checks(tmp_path):
    report = check_devices(
        usb_backend=UsbCameraSim(speaks_wire=False),
        probe_camera_wire=True,
        turntable_port=str(tmp_path / "no-such-port"),
    )
    assert report.check("camera").status == "error"
    assert "does not speak the toftwin USB wire protocol" in report.check("camera").detail
    turntable = report.check("turntable")
    assert turntable.status == "error" and "DeviceDisconnectedError" in turntable.detail


def test_device_check_status_is_checked():
    with pytest.raises(ValueError, match="status 'fine'"):
        DeviceCheck("camera", "fine", "")
    assert DeviceReport([DeviceCheck("x", "warning", "")]).ok
