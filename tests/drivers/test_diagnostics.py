"""Device diagnostics: the camera list and the device check the CLI runs."""

from __future__ import annotations

import json

import pytest

from drivers.camera import discover
from drivers.diagnostics import DeviceCheck, DeviceReport, check_devices, list_devices
from drivers.sim.pty_server import start_simulator
from drivers.sim.usb_camera import UsbCameraSim
from tests.drivers.helpers import ROYALE_RULE

pytestmark = pytest.mark.timeout(20)


def test_list_devices_gives_the_discovered_pmd_devices_as_plain_dicts():
    bus = UsbCameraSim(serial="A-OK", address=4)
    bus.add_device(serial="B-DENIED", address=5, access="denied")
    bus.add_device(vendor_id=0x046D, product_id=0x0825, product="webcam", address=8)
    devices = list_devices(bus)
    assert [d["serial"] for d in devices] == ["A-OK", None]
    assert devices == [info.to_dict() for info in discover(bus)]
    json.dumps(devices)  # plain data for the CLI


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
    assert "wire protocol v2, one MODE_5_45FPS_500 frame (1, 4, 171, 224) read" in camera.detail
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
