"""Finding PMD cameras on the USB bus, and telling why one cannot be opened.

:func:`discover` is plain pyusb and works on real hardware: every device with PMD's vendor id
0x1C28 is listed (:class:`UsbDeviceInfo`) with serial number, product and USB speed, and a device
that is present but cannot be opened (permissions / a missing udev rule, a kernel driver, another
program holding it) is reported with the fix.

The public names outside ``__all__`` (:data:`INTERFACE`, the ``LIBUSB_*`` error codes,
:func:`find_backend`, :func:`is_usb_error`, :func:`open_probe`, :func:`bcd`, the fix texts
:func:`permission_fix` and :data:`BUSY_FIX`) are shared with the streaming driver
:mod:`drivers.camera.usb_driver`, which opens the same devices and reports the same problems.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
from dataclasses import dataclass
from typing import Any

import usb.core
import usb.util

from drivers.camera.protocol import CameraError

__all__ = [
    "KNOWN_PRODUCTS",
    "PICO_FLEXX_PRODUCT_ID",
    "PMD_VENDOR_ID",
    "USB_SPEEDS",
    "UsbBackendError",
    "UsbDeviceInfo",
    "discover",
    "udev_rule",
]

#: USB vendor id of pmdtechnologies ag (all PMD camera modules).
PMD_VENDOR_ID = 0x1C28
#: USB product id of the CamBoard pico flexx.
PICO_FLEXX_PRODUCT_ID = 0xC012
#: PMD product ids we know a name for (from royale's udev rules file 10-royale-ubuntu.rules).
KNOWN_PRODUCTS: dict[int, str] = {0xC012: "pico flexx", 0xC00F: "pico s"}
#: libusb speed codes (``usb.core.Device.speed``) -> text.
USB_SPEEDS: dict[int, str] = {
    0: "unknown",
    1: "low (1.5 Mbit/s)",
    2: "full (12 Mbit/s)",
    3: "high (480 Mbit/s)",
    4: "super (5 Gbit/s)",
    5: "super+ (10 Gbit/s)",
}

#: The camera's one interface (its bulk IN endpoint carries the frames).
INTERFACE = 0

# libusb error codes as pyusb's libusb1 backend reports them in ``backend_error_code``.
LIBUSB_ACCESS = -3
LIBUSB_NO_DEVICE = -4
LIBUSB_BUSY = -6
LIBUSB_PIPE = -9


class UsbBackendError(CameraError):
    """pyusb has no usable backend (libusb is not installed)."""


@dataclass(frozen=True)
class UsbDeviceInfo:
    """One PMD device found on the bus (see :func:`discover`).

    ``accessible`` is False when the device cannot be opened or its interface claimed;
    ``problem`` says why and ``fix`` what to do. A kernel driver bound to the interface is
    reported in ``notes`` (the driver detaches it when it connects).
    """

    vendor_id: int
    product_id: int
    model: str
    bus: int | None
    address: int | None
    port_path: str | None
    speed: str
    usb_version: str
    firmware: str
    serial: str | None
    product: str | None
    manufacturer: str | None
    accessible: bool
    problem: str | None = None
    fix: str | None = None
    kernel_driver_active: bool | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict; ids as 4 hex digits (``"1c28"``) as lsusb prints them."""
        data = dataclasses.asdict(self)
        data["vendor_id"] = f"{self.vendor_id:04x}"
        data["product_id"] = f"{self.product_id:04x}"
        data["notes"] = list(self.notes)
        return data


def udev_rule(product_id: int = PICO_FLEXX_PRODUCT_ID, vendor_id: int = PMD_VENDOR_ID) -> str:
    """The udev rule line that lets users of group ``plugdev`` open the camera.

    The line royale's ``10-royale-ubuntu.rules`` has for the pico flexx.

    >>> udev_rule().split(", ")[:3]
    ['SUBSYSTEMS=="usb"', 'ATTRS{idVendor}=="1c28"', 'ATTRS{idProduct}=="c012"']
    """
    name = KNOWN_PRODUCTS.get(product_id, f"pmd_{product_id:04x}").replace(" ", "_")
    return (
        f'SUBSYSTEMS=="usb", ATTRS{{idVendor}}=="{vendor_id:04x}", '
        f'ATTRS{{idProduct}}=="{product_id:04x}", MODE="0666", '
        f'SYMLINK+="camboard_{name}-%k", GROUP="plugdev"'
    )


def permission_fix(product_id: int) -> str:
    """What to do when opening the camera is not permitted: the udev rule and how to load it."""
    return (
        "add the udev rule line\n    " + udev_rule(product_id) + "\nto "
        "/etc/udev/rules.d/10-royale-ubuntu.rules, run 'sudo udevadm control --reload-rules "
        "&& sudo udevadm trigger', make sure you are in group plugdev, and replug the camera"
    )


BUSY_FIX = (
    "close the other program that has the camera open (royaleviewer, another toftwin process, "
    "a sample), then retry"
)


def _kernel_driver_fix(product_id: int) -> str:
    return (
        "let the driver detach it when it connects (UsbCameraSettings.detach_kernel_driver, the "
        "default), or unbind it: echo -n '<bus>-<port>:1.0' | sudo tee "
        f"/sys/bus/usb/drivers/<driver>/unbind (device 1c28:{product_id:04x})"
    )


def find_backend(backend: Any) -> Any:
    """The pyusb backend to use: ``backend`` or the first of libusb1, openusb, libusb0."""
    if backend is not None:
        return backend
    import usb.backend.libusb0 as libusb0
    import usb.backend.libusb1 as libusb1
    import usb.backend.openusb as openusb

    for module in (libusb1, openusb, libusb0):
        found = module.get_backend()
        if found is not None:
            return found
    raise UsbBackendError(
        "cannot list USB devices: pyusb found no backend (libusb is not installed). "
        "Fix: install libusb 1.0 (Debian/Ubuntu: sudo apt-get install libusb-1.0-0; "
        "macOS: brew install libusb)"
    )


def is_usb_error(exc: BaseException, code: int, err: int) -> bool:
    """True if ``exc`` is a pyusb error with libusb code ``code`` or errno ``err``."""
    return isinstance(exc, usb.core.USBError) and (
        getattr(exc, "backend_error_code", None) == code or exc.errno == err
    )


def bcd(value: int) -> str:
    """A BCD version word as text: ``0x0210`` -> ``"2.10"``."""
    return f"{value >> 8:x}.{value & 0xFF:02x}"


def open_probe(dev: Any) -> bool | None:
    """Open the device and ask whether a kernel driver holds interface 0.

    Opening is what fails without permission, with LIBUSB_ERROR_ACCESS (reading the string
    descriptors first would only give pyusb's vaguer "no langid"). None where the platform
    cannot tell (libusb on Windows and macOS).
    """
    try:
        return bool(dev.is_kernel_driver_active(INTERFACE))
    except NotImplementedError:
        return None


def _describe_device(dev: Any) -> UsbDeviceInfo:
    """Identity and accessibility of one enumerated device (opens it to read the strings)."""
    vid, pid = int(dev.idVendor), int(dev.idProduct)
    model = (
        KNOWN_PRODUCTS.get(pid, f"PMD device {pid:04x}")
        if vid == PMD_VENDOR_ID
        else (f"device {vid:04x}:{pid:04x}")
    )
    ports = getattr(dev, "port_numbers", None)
    port_path = (
        f"{dev.bus}-{'.'.join(str(p) for p in ports)}" if ports and dev.bus is not None else None
    )
    serial = product = manufacturer = None
    accessible, problem, fix = True, None, None
    kernel: bool | None = None
    notes: list[str] = []
    try:
        kernel = open_probe(dev)
        serial = dev.serial_number
        product = dev.product
        manufacturer = dev.manufacturer
    except usb.core.USBError as exc:
        accessible = False
        if is_usb_error(exc, LIBUSB_ACCESS, errno.EACCES):
            problem = f"permission denied opening the device ({exc})"
            fix = permission_fix(pid)
        elif is_usb_error(exc, LIBUSB_BUSY, errno.EBUSY):
            problem = f"device busy ({exc})"
            fix = BUSY_FIX
        else:
            problem = f"cannot open the device or read its string descriptors ({exc})"
            fix = "replug the camera; if it persists, check 'dmesg' for USB errors"
    except ValueError as exc:  # pyusb: "The device has no langid (permission issue, ...)"
        accessible = False
        problem = f"cannot read the string descriptors ({exc})"
        fix = permission_fix(pid)
    if kernel:
        notes.append(
            f"a kernel driver is bound to interface {INTERFACE}; fix: " + _kernel_driver_fix(pid)
        )
    with contextlib.suppress(usb.core.USBError):
        usb.util.dispose_resources(dev)
    return UsbDeviceInfo(
        vendor_id=vid,
        product_id=pid,
        model=model,
        bus=dev.bus,
        address=dev.address,
        port_path=port_path,
        speed=USB_SPEEDS.get(dev.speed or 0, f"code {dev.speed}"),
        usb_version=bcd(int(dev.bcdUSB)),
        firmware=bcd(int(dev.bcdDevice)),
        serial=serial,
        product=product,
        manufacturer=manufacturer,
        accessible=accessible,
        problem=problem,
        fix=fix,
        kernel_driver_active=kernel,
        notes=tuple(notes),
    )


def discover(
    backend: Any = None, *, vendor_id: int = PMD_VENDOR_ID, product_id: int | None = None
) -> list[UsbDeviceInfo]:
    """Every USB device with ``vendor_id`` (PMD by default), sorted by bus and address.

    Works on real hardware (libusb) and on a simulated backend. Raises
    :class:`UsbBackendError` with the fix when pyusb has no backend.
    """
    be = find_backend(backend)
    match: dict[str, int] = {"idVendor": vendor_id}
    if product_id is not None:
        match["idProduct"] = product_id
    devices = list(usb.core.find(find_all=True, backend=be, **match))
    infos = [_describe_device(dev) for dev in devices]
    return sorted(infos, key=lambda i: (i.bus or 0, i.address or 0))
