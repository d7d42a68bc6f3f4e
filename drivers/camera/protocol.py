"""The contract of a ToF camera driver, shared by every backend.

:class:`CameraProtocol` is what the service, the pose loop and :class:`drivers.rig.Rig` need
from a camera; two backends implement it and return :class:`~sim_core.raw.RawFrame` s:
:class:`drivers.camera.usb_driver.UsbCamera` (our USB wire format over pyusb) and
:class:`drivers.camera.royale.RoyaleCamera` (a real pico flexx through PMD's royale SDK).
Both describe the camera with a :class:`CameraIdentity` and fail with :class:`CameraError`
(a :class:`~drivers.errors.DeviceError`) and its subclasses.

(:class:`sim_core.camera.Camera` is something else: the pinhole model of the optics.)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from drivers.camera.wire import UseCase
from drivers.errors import DeviceDisconnectedError, DeviceError
from sim_core.raw import RawFrame

__all__ = [
    "CameraAccessError",
    "CameraError",
    "CameraIdentity",
    "CameraLostError",
    "CameraNotFoundError",
    "CameraProtocol",
]


# -- errors --------------------------------------------------------------------------------
class CameraError(DeviceError):
    """The camera, its USB connection or its SDK did not do what was asked."""


class CameraNotFoundError(CameraError):
    """No matching camera is enumerated on the bus."""


class CameraLostError(CameraError, DeviceDisconnectedError):
    """The camera, or the camera bridge it is reached through, went away mid-use (unplugged, the
    bridge or its SDK killed): it may come back, and a campaign it paused watches for it
    (:mod:`service.lab.camera_return`)."""


class CameraAccessError(CameraError):
    """The camera is present but cannot be opened or claimed.

    Attributes
    ----------
    fix : str
        What to do about it (a udev rule, closing another program, ...).
    """

    def __init__(self, message: str, fix: str) -> None:
        self.fix = fix
        super().__init__(f"{message}. Fix: {fix}")


# -- identity ------------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraIdentity:
    """Who the camera is.

    Attributes
    ----------
    model : str
        ``"pico flexx"`` (from the product id) or royale's camera name.
    serial : str
        USB serial number string or royale camera id.
    product, manufacturer : str or None
        USB string descriptors.
    vendor_id, product_id : int or None
    firmware : str or None
        ``bcdDevice`` as ``"1.00"``, or what the SDK reports.
    usb_speed : str or None
        Text from :data:`drivers.camera.discovery.USB_SPEEDS`.
    bus, address : int or None
    backend : str
        ``"pyusb"`` or ``"royale"``.
    extra : dict
        Anything else the backend knows (royale's camera info pairs, wire version, ...).
    """

    model: str
    serial: str
    product: str | None = None
    manufacturer: str | None = None
    vendor_id: int | None = None
    product_id: int | None = None
    firmware: str | None = None
    usb_speed: str | None = None
    bus: int | None = None
    address: int | None = None
    backend: str = "pyusb"
    extra: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# -- the interface the rest of the code depends on ------------------------------------------
@runtime_checkable
class CameraProtocol(Protocol):
    """What the service and the pose loop need from a ToF camera.

    ``capture(n)`` returns ``n`` complete, checked raw frames of the configured use case. When
    the camera is not streaming it is started for the capture and stopped afterwards, so every
    frame was exposed after the call; when it is streaming, the next ``n`` frames are returned.
    Bad frames are skipped and counted, or raise, as the backend is configured; a missing stream
    raises :class:`~drivers.errors.DeviceTimeoutError` - ``capture`` never hangs.
    """

    @property
    def use_case(self) -> UseCase:
        """The configured use case."""
        ...

    def configure(self, use_case: str | UseCase) -> None:
        """Select a use case by royale name (``"MODE_9_5FPS_2000"``); restarts a running stream."""
        ...

    def start(self) -> None:
        """Start streaming (no-op if streaming)."""
        ...

    def stop(self) -> None:
        """Stop streaming (no-op if stopped)."""
        ...

    def capture(self, n: int = 1) -> list[RawFrame]:
        """The next ``n`` raw frames (phase images as C = raw - 2048 DN, float32)."""
        ...

    def identity(self) -> CameraIdentity:
        """Model, serial number, firmware, connection."""
        ...

    def close(self) -> None:
        """Stop streaming and release the device; safe to call twice."""
        ...
