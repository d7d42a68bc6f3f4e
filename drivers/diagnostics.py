"""Device diagnostics: list the cameras present, check every device of the rig.

- :func:`list_devices` lists PMD cameras on the USB bus as plain dicts (one per device): ids,
  model, serial number, product string, USB speed and version, bus / address / port, and whether
  the device can be opened - when not, ``problem`` says why and ``fix`` what to do (the udev rule
  line to add, the other program to close).
- :func:`check_devices` runs one check per device of the rig (camera on USB, royale for real
  streaming, turntable, solar simulator) and returns a :class:`DeviceReport`; every check is
  bounded by the drivers' timeouts and none raises.

Neither function prints; the CLI (``toftwin devices``) formats
``report.to_dict()`` or ``str(report)``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.camera import (
    PICO_FLEXX_PRODUCT_ID,
    PMD_VENDOR_ID,
    UsbCamera,
    UsbCameraSettings,
    discover,
)
from drivers.camera.royale import INSTALL_HINT, royale_available
from drivers.errors import DeviceError

__all__ = ["DeviceCheck", "DeviceReport", "check_devices", "list_devices"]

_STATUSES = ("ok", "warning", "error", "skipped")


def list_devices(backend: Any = None, *, vendor_id: int = PMD_VENDOR_ID) -> list[dict[str, Any]]:
    """PMD USB devices present, one dict each (see :class:`drivers.camera.UsbDeviceInfo`).

    Raises :class:`drivers.camera.UsbBackendError` (with the fix) when pyusb finds no libusb.

    Examples
    --------
    >>> from drivers.sim.usb_camera import UsbCameraSim
    >>> [d["model"] for d in list_devices(UsbCameraSim())]
    ['pico flexx']
    """
    return [info.to_dict() for info in discover(backend, vendor_id=vendor_id)]


@dataclass(frozen=True)
class DeviceCheck:
    """The outcome of checking one device.

    Attributes
    ----------
    name : str
        ``"camera"``, ``"royale"``, ``"turntable"``, ``"solar simulator"``.
    status : {"ok", "warning", "error", "skipped"}
    detail : str
        What was found (or went wrong).
    fix : str or None
        What to do about an error or warning.
    data : dict
        Machine-readable findings (device list, identity, status).
    """

    name: str
    status: str
    detail: str
    fix: str | None = None
    data: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.status not in _STATUSES:
            raise ValueError(f"status {self.status!r}; one of {_STATUSES}")


@dataclass(frozen=True)
class DeviceReport:
    """All checks; ``ok`` unless one of them is an error."""

    checks: list[DeviceCheck]

    @property
    def ok(self) -> bool:
        return all(c.status != "error" for c in self.checks)

    def check(self, name: str) -> DeviceCheck:
        """The check called ``name``."""
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(name)

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "checks": [dataclasses.asdict(c) for c in self.checks]}

    def __str__(self) -> str:
        lines = []
        for c in self.checks:
            lines.append(f"[{c.status:>7}] {c.name}: {c.detail}")
            if c.fix:
                lines.extend("          fix: " + line for line in c.fix.splitlines())
        return "\n".join(lines)


def _guard(name: str, check: Callable[[], DeviceCheck]) -> DeviceCheck:
    """Run one check; a driver error becomes an "error" check instead of an exception."""
    try:
        return check()
    except (DeviceError, OSError, ValueError) as exc:
        return DeviceCheck(name, "error", f"{type(exc).__name__}: {exc}", getattr(exc, "fix", None))


def _check_camera(backend: Any, serial: str | None, probe_wire: bool) -> DeviceCheck:
    found = discover(backend)
    devices = [d.to_dict() for d in found]
    cameras = [d for d in found if d.product_id == PICO_FLEXX_PRODUCT_ID]
    if serial is not None:
        cameras = [d for d in cameras if d.serial == serial]
    if not cameras:
        which = f" with serial {serial!r}" if serial else ""
        return DeviceCheck(
            "camera",
            "error",
            f"no pico flexx (1c28:c012){which} on the USB bus ({len(found)} other PMD device(s))",
            "plug the camera in (a USB 3 port or a powered hub); 'lsusb -d 1c28:' lists it",
            {"devices": devices},
        )
    cam = cameras[0]
    if not cam.accessible:
        return DeviceCheck(
            "camera",
            "error",
            f"pico flexx on bus {cam.bus} address {cam.address} is present "
            f"but not accessible: {cam.problem}",
            cam.fix,
            {"devices": devices},
        )
    detail = (
        f"pico flexx serial {cam.serial} ({cam.product}), USB {cam.usb_version} "
        f"{cam.speed}, bus {cam.bus} address {cam.address}"
    )
    data: dict[str, Any] = {"devices": devices}
    status, fix = "ok", None
    if cam.notes:
        status, fix = "warning", "; ".join(cam.notes)
    if probe_wire:
        settings = UsbCameraSettings(read_timeout_s=1.0, reconnect_timeout_s=0.0)
        with UsbCamera(cam.serial, backend=backend, settings=settings) as usb_cam:
            st = usb_cam.status()
            frame = usb_cam.capture(1)[0]
            data["status"] = dataclasses.asdict(st)
            data["identity"] = usb_cam.identity().to_dict()
        detail += (
            f"; wire protocol v{st.wire_version}, one {usb_cam.use_case.name} frame "
            f"{frame.phase_images.shape} read"
        )
    return DeviceCheck("camera", status, detail, fix, data)


def _check_royale() -> DeviceCheck:
    if royale_available():
        return DeviceCheck("royale", "ok", "roypy imports: streaming from a pico flexx available")
    return DeviceCheck(
        "royale",
        "warning",
        "royale not installed: a real pico flexx can be listed but not streamed",
        INSTALL_HINT,
    )


def _check_turntable(port: str, address: int) -> DeviceCheck:
    from drivers.turntable import Turntable

    with Turntable(port, address=address) as tt:
        status = tt.status()
        position = tt.position_deg()
        low, high = tt.limits_deg
        data = {
            "state": status.state,
            "error_bits": status.error_bits,
            "position_deg": position,
            "limits_deg": [low, high],
            "stage": tt.stage_name,
        }
    level = "ok" if status.is_referenced and not status.error_bits else "warning"
    fix = None if level == "ok" else "home the stage (Turntable.home) or clear the error (MM1)"
    return DeviceCheck(
        "turntable",
        level,
        f"SMC100 at {port}: {status.describe()}, position {position:g} deg, "
        f"limits [{low:g}, {high:g}] deg, stage {tt.stage_name}",
        fix,
        data,
    )


def _check_solar(lamp_port: str, shutter_port: str) -> DeviceCheck:
    from drivers.solar_simulator import SolarSimulator

    with SolarSimulator(lamp_port, shutter_port) as solar:
        status = solar.status()
        hours = solar.lamp_hours()
        data = {
            "stb": status.stb,
            "lamp_on": status.lamp_on,
            "shutter_open": status.shutter_open,
            "lamp_hours": hours,
            "model": solar.model_id,
            "shutter_model": solar.shutter_model_id,
        }
    level = "error" if status.fault or status.interlock else "ok"
    fix = "close the interlock / check the lamp, then clear the fault" if level == "error" else None
    return DeviceCheck(
        "solar simulator",
        level,
        f"lamp supply {solar.model_id} at {lamp_port}, shutter "
        f"{solar.shutter_model_id} at {shutter_port}: {status.describe()}, lamp {hours:g} h",
        fix,
        data,
    )


def check_devices(
    *,
    usb_backend: Any = None,
    camera_serial: str | None = None,
    probe_camera_wire: bool = False,
    turntable_port: str | None = None,
    turntable_address: int = 1,
    lamp_port: str | None = None,
    shutter_port: str | None = None,
) -> DeviceReport:
    """Check every device of the rig; a device without a port is "skipped".

    Parameters
    ----------
    usb_backend : pyusb backend or None
        libusb when None; a :class:`drivers.sim.usb_camera.UsbCameraSim` for the simulator.
    camera_serial : str or None
        Which pico flexx (the first when None).
    probe_camera_wire : bool
        Also open the camera with :class:`drivers.camera.UsbCamera` and read one frame. Only
        for devices speaking our wire format (the simulator): a real pico flexx streams through
        royale and is not sent our vendor requests unless this is set.
    turntable_port, turntable_address : str or None, int
        SMC100 port and RS-485 address.
    lamp_port, shutter_port : str or None
        Oriel lamp supply and exposure controller ports (both, or the check is skipped).
    """
    checks = [
        _guard("camera", lambda: _check_camera(usb_backend, camera_serial, probe_camera_wire)),
        _guard("royale", _check_royale),
    ]
    if turntable_port is None:
        checks.append(DeviceCheck("turntable", "skipped", "no port given"))
    else:
        checks.append(
            _guard("turntable", lambda: _check_turntable(turntable_port, turntable_address))
        )
    if lamp_port is None or shutter_port is None:
        checks.append(DeviceCheck("solar simulator", "skipped", "lamp and shutter ports not given"))
    else:
        checks.append(_guard("solar simulator", lambda: _check_solar(lamp_port, shutter_port)))
    return DeviceReport(checks)
