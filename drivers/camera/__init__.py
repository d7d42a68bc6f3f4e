"""The ToF camera (a PMD pico flexx on USB): its driver contract, discovery and two backends.

One job per module:

- :mod:`drivers.camera.protocol`: :class:`CameraProtocol`, what the rest of the code needs from
  a camera, with :class:`CameraIdentity` and the :class:`CameraError` family.
- :mod:`drivers.camera.discovery`: :func:`discover` lists PMD devices on the USB bus and says why
  one cannot be opened (with the fix, e.g. the :func:`udev_rule` line).
- :mod:`drivers.camera.wire`: our USB wire format for raw frames, pure encode / decode functions.
- :mod:`drivers.camera.usb_driver`: :class:`UsbCamera`, that wire format over pyusb (the
  simulator :class:`drivers.sim.usb_camera.UsbCameraSim` speaks it).
- :mod:`drivers.camera.royale`: :class:`RoyaleCamera`, a real pico flexx through PMD's royale SDK
  (``roypy``; this package imports without it).

Import the public names from here: ``from drivers.camera import UsbCamera, CameraProtocol``.
"""

from drivers.camera.discovery import (
    KNOWN_PRODUCTS,
    PICO_FLEXX_PRODUCT_ID,
    PMD_VENDOR_ID,
    USB_SPEEDS,
    UsbBackendError,
    UsbDeviceInfo,
    discover,
    udev_rule,
)
from drivers.camera.protocol import (
    CameraAccessError,
    CameraError,
    CameraIdentity,
    CameraNotFoundError,
    CameraProtocol,
)
from drivers.camera.royale import RoyaleCamera, RoyaleNotInstalledError, royale_available
from drivers.camera.usb_driver import (
    CaptureStats,
    FrameDroppedError,
    UsbCamera,
    UsbCameraSettings,
)
from drivers.camera.wire import (
    USE_CASES,
    CorruptFrameError,
    FrameError,
    TruncatedFrameError,
    UseCase,
    get_use_case,
)

__all__ = [
    "KNOWN_PRODUCTS",
    "PICO_FLEXX_PRODUCT_ID",
    "PMD_VENDOR_ID",
    "USB_SPEEDS",
    "USE_CASES",
    "CameraAccessError",
    "CameraError",
    "CameraIdentity",
    "CameraNotFoundError",
    "CameraProtocol",
    "CaptureStats",
    "CorruptFrameError",
    "FrameDroppedError",
    "FrameError",
    "RoyaleCamera",
    "RoyaleNotInstalledError",
    "TruncatedFrameError",
    "UsbBackendError",
    "UsbCamera",
    "UsbCameraSettings",
    "UsbDeviceInfo",
    "UseCase",
    "discover",
    "get_use_case",
    "royale_available",
    "udev_rule",
]
