"""Discovery of PMD cameras on the USB bus: identity, access problems and their fixes."""

from __future__ import annotations

import json

import pytest
import usb.backend.libusb0
import usb.backend.libusb1
import usb.backend.openusb

from drivers.camera import UsbBackendError, discover, udev_rule
from drivers.sim.usb_camera import UsbCameraSim
from tests.drivers.helpers import ROYALE_RULE

pytestmark = pytest.mark.timeout(20)


@pytest.fixture
def bus():
    """A bus with four PMD cameras in different conditions and one webcam of another vendor."""
    sim = UsbCameraSim(serial="A-OK", address=4)
    sim.add_device(serial="B-DENIED", address=5, access="denied")
    sim.add_device(serial="C-KERNEL", address=6, kernel_driver_active=True)
    sim.add_device(serial="D-USB1", address=7, speed=2, usb_version=0x0110, bus=2)
    sim.add_device(vendor_id=0x046D, product_id=0x0825, product="webcam", address=8)
    return sim


def _listed(backend=None):
    """What discovery finds, as the plain dicts the CLI prints."""
    return [info.to_dict() for info in discover(backend)]


def test_lists_pmd_cameras_with_serial_product_and_speed(bus):
    devices = _listed(bus)
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
    denied = _listed(bus)[1]
    assert denied["accessible"] is False
    assert denied["problem"].startswith("permission denied opening the device")
    assert ROYALE_RULE in denied["fix"]
    assert "udevadm control --reload-rules" in denied["fix"]
    assert denied["product_id"] == "c012" and denied["address"] == 5  # still identified


def test_a_bound_kernel_driver_is_noted_with_the_fix(bus):
    kernel = _listed(bus)[2]
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
        discover()
