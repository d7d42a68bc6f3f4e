"""The pyusb streaming driver :class:`UsbCamera`: our USB wire format, over pyusb.

:class:`UsbCamera` implements :class:`~drivers.camera.protocol.CameraProtocol` for a device
speaking *our* wire format (:mod:`drivers.camera.wire`, ``docs/devices.md`` "Camera (USB)"):
vendor control requests to configure a use case and to start / stop streaming, one bulk IN
transfer per raw frame, reassembled from packets and checked (sequence numbers, lengths, CRC32).
The simulator :class:`drivers.sim.usb_camera.UsbCameraSim` is a pyusb backend that speaks it; a
real pico flexx does **not** (it streams through PMD's royale SDK:
:class:`drivers.camera.royale.RoyaleCamera`).

Errors: :class:`~drivers.camera.protocol.CameraError` and its subclasses; bad frames raise
:class:`~drivers.camera.wire.FrameError` subclasses (a ProtocolError), a sequence gap
:class:`FrameDroppedError`; a missing frame stream raises
:class:`~drivers.errors.DeviceTimeoutError`; a camera that was unplugged and did not come back
raises :class:`~drivers.errors.DeviceDisconnectedError`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import usb.core
import usb.util

from drivers.camera.discovery import (
    BUSY_FIX,
    INTERFACE,
    KNOWN_PRODUCTS,
    LIBUSB_ACCESS,
    LIBUSB_BUSY,
    LIBUSB_NO_DEVICE,
    LIBUSB_PIPE,
    PICO_FLEXX_PRODUCT_ID,
    PMD_VENDOR_ID,
    USB_SPEEDS,
    bcd,
    find_backend,
    is_usb_error,
    open_probe,
    permission_fix,
)
from drivers.camera.protocol import (
    CameraAccessError,
    CameraError,
    CameraIdentity,
    CameraNotFoundError,
)
from drivers.camera.wire import (
    READABLE_VERSIONS,
    STATUS_SIZE,
    CorruptFrameError,
    DeviceStatus,
    FrameError,
    Request,
    RequestType,
    TruncatedFrameError,
    UseCase,
    decode_frame,
    decode_status,
    get_use_case,
    wire_to_raw_frame,
)
from drivers.errors import (
    DeviceDisconnectedError,
    DeviceError,
    DeviceInputError,
    DeviceTimeoutError,
)
from sim_core.raw import RawFrame

__all__ = ["CaptureStats", "FrameDroppedError", "UsbCamera", "UsbCameraSettings"]

_log = logging.getLogger(__name__)

#: The camera's bulk IN endpoint: one transfer per raw frame.
_BULK_IN = 0x81


class FrameDroppedError(FrameError):
    """Frames are missing from the stream (a gap in the sequence numbers).

    Attributes
    ----------
    missing : int
        How many sequence numbers were skipped.
    """

    def __init__(self, message: str, sequence: int, missing: int) -> None:
        self.missing = missing
        super().__init__("dropped", message, sequence)


# -- the pyusb streaming driver -------------------------------------------------------------
@dataclass(frozen=True)
class UsbCameraSettings:
    """How :class:`UsbCamera` reads and how hard it tries.

    Attributes
    ----------
    read_timeout_s : float
        Timeout of one bulk read; a frame must start arriving within it.
    no_data_retries : int
        Extra bulk reads after a timeout before :class:`DeviceTimeoutError` is raised.
    chunk_bytes : int
        Size of one bulk read request; rounded up to a multiple of the endpoint's
        ``wMaxPacketSize``. A frame is reassembled from reads until a short packet ends it.
    on_bad_frame : {"skip", "raise"}
        ``"skip"``: a truncated or corrupt frame is counted and the next one read; a sequence
        gap is counted in ``stats.dropped``. ``"raise"``: the :class:`FrameError` (or
        :class:`FrameDroppedError`) propagates.
    max_bad_frames : int
        In ``"skip"`` mode, bad frames in a row after which the last error is raised.
    ctrl_timeout_s : float
        Timeout of a control request.
    reconnect_timeout_s : float
        How long to wait for an unplugged camera to come back before
        :class:`DeviceDisconnectedError`.
    reconnect_poll_s : float
        Period of the bus scans while waiting.
    detach_kernel_driver : bool
        Detach a kernel driver bound to the interface when connecting (Linux).
    """

    read_timeout_s: float = 1.0
    no_data_retries: int = 2
    chunk_bytes: int = 65536
    on_bad_frame: str = "skip"
    max_bad_frames: int = 8
    ctrl_timeout_s: float = 1.0
    reconnect_timeout_s: float = 5.0
    reconnect_poll_s: float = 0.05
    detach_kernel_driver: bool = True

    def __post_init__(self) -> None:
        for name in ("read_timeout_s", "ctrl_timeout_s", "reconnect_poll_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise DeviceInputError(name, f"got {value!r}; a finite number > 0 is required")
        if not (self.reconnect_timeout_s >= 0):
            raise DeviceInputError(
                "reconnect_timeout_s", f"got {self.reconnect_timeout_s!r}; >= 0 is required"
            )
        if self.on_bad_frame not in ("skip", "raise"):
            raise DeviceInputError("on_bad_frame", f"got {self.on_bad_frame!r}; 'skip' or 'raise'")
        for name in ("no_data_retries", "max_bad_frames"):
            if getattr(self, name) < 0:
                raise DeviceInputError(name, f"got {getattr(self, name)!r}; 0 or more")
        if self.chunk_bytes < 1:
            raise DeviceInputError("chunk_bytes", f"got {self.chunk_bytes!r}; at least 1")


@dataclass
class CaptureStats:
    """Running counts of what the stream delivered since the driver was created."""

    frames: int = 0
    dropped: int = 0
    truncated: int = 0
    corrupt: int = 0
    invalid: int = 0
    timeouts: int = 0
    reconnects: int = 0

    def to_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


#: Frame errors raised after the header CRC was checked: their sequence number is reliable.
_TRUSTED_SEQUENCE = frozenset(
    {"header", "length", "truncated", "payload-crc", "values", "use-case"}
)


def _ms(seconds: float) -> int:
    # libusb reads a timeout of 0 as "wait forever": never send 0.
    return max(1, round(seconds * 1000))


class UsbCamera:
    """A camera speaking our USB wire format, driven through pyusb.

    Parameters
    ----------
    serial : str or None
        Serial number to open; the first matching device when None.
    backend : pyusb backend or None
        ``drivers.sim.usb_camera.UsbCameraSim`` for the simulator; libusb when None.
    use_case : str
        Use case configured at :meth:`connect`.
    vendor_id, product_id : int
        Which devices to consider.
    settings : UsbCameraSettings

    Not thread-safe: one thread at a time (a :class:`drivers.rig.Rig` serialises access).

    Examples
    --------
    >>> from drivers.sim.usb_camera import UsbCameraSim, plane_source
    >>> sim = UsbCameraSim(plane_source(distance_m=1.5), seed=1)
    >>> with UsbCamera(backend=sim) as cam:
    ...     frames = cam.capture(2)
    >>> frames[0].phase_images.shape, frames[0].phase_images.dtype
    ((1, 4, 171, 224), dtype('float32'))
    """

    def __init__(
        self,
        serial: str | None = None,
        *,
        backend: Any = None,
        use_case: str | UseCase = "MODE_5_45FPS_500",
        vendor_id: int = PMD_VENDOR_ID,
        product_id: int = PICO_FLEXX_PRODUCT_ID,
        settings: UsbCameraSettings | None = None,
    ) -> None:
        self.serial = serial
        self.vendor_id = vendor_id
        self.product_id = product_id
        self.settings = settings or UsbCameraSettings()
        self._use_case = get_use_case(use_case)
        self._backend_arg = backend
        self._backend: Any = None
        self._dev: Any = None
        self._chunk = self.settings.chunk_bytes
        self._max_packet = 512
        self._streaming = False
        self._expected_seq: int | None = None
        self._identity: CameraIdentity | None = None
        self.stats = CaptureStats()
        self.name = "USB camera"

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Find and open the camera, check it speaks our wire version, configure the use case.

        Raises :class:`CameraNotFoundError`, :class:`CameraAccessError` (with the fix),
        :class:`UsbBackendError`, :class:`CameraError` (wrong wire version).
        """
        if self._dev is not None:
            return
        self._backend = find_backend(self._backend_arg)
        # once identified, stay with that camera (a reconnect must not pick up another one)
        serial = self.serial or (self._identity.serial if self._identity else None)
        dev = self._find(serial)
        if dev is None:
            which = f"serial {serial!r}" if serial else "any serial"
            raise CameraNotFoundError(
                f"no camera {self.vendor_id:04x}:{self.product_id:04x} ({which}) on the USB bus; "
                "is it plugged in? ('lsusb -d 1c28:' lists PMD devices)"
            )
        self._open(dev)

    def __enter__(self) -> UsbCamera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop streaming (best effort) and release the interface; safe to call twice."""
        if self._dev is None:
            return
        if self._streaming:
            with contextlib.suppress(DeviceError, usb.core.USBError):
                self._ctrl_out(Request.STOP, 0, "STOP")
        self._streaming = False
        self._release()

    @property
    def is_connected(self) -> bool:
        return self._dev is not None

    @property
    def is_streaming(self) -> bool:
        return self._streaming

    def _find(self, serial: str | None = None) -> Any:
        """The first matching device present (with ``serial`` if given), or None."""
        serial = serial if serial is not None else self.serial

        def match(dev: Any) -> bool:
            if serial is None:
                return True
            try:
                return dev.serial_number == serial
            except (usb.core.USBError, ValueError):
                return False  # an inaccessible device is not the one we can open

        return usb.core.find(
            backend=self._backend,
            idVendor=self.vendor_id,
            idProduct=self.product_id,
            custom_match=match,
        )

    def _open(self, dev: Any) -> None:
        """Open, detach a kernel driver, configure, claim; read identity and status."""
        pid = int(dev.idProduct)
        where = f"camera {self.vendor_id:04x}:{pid:04x} on bus {dev.bus} address {dev.address}"
        try:
            kernel = open_probe(dev)
            serial = dev.serial_number
            if kernel and self.settings.detach_kernel_driver:
                _log.info("%s: detaching kernel driver from interface 0", where)
                dev.detach_kernel_driver(INTERFACE)
            try:
                cfg = dev.get_active_configuration()
            except usb.core.USBError:
                cfg = None
            if cfg is None or cfg.bConfigurationValue != 1:
                dev.set_configuration(1)
            usb.util.claim_interface(dev, INTERFACE)
            intf = dev.get_active_configuration()[(INTERFACE, 0)]
            ep = usb.util.find_descriptor(intf, bEndpointAddress=_BULK_IN)
        except usb.core.USBError as exc:
            with contextlib.suppress(usb.core.USBError):
                usb.util.dispose_resources(dev)
            if is_usb_error(exc, LIBUSB_ACCESS, errno.EACCES):
                raise CameraAccessError(
                    f"{where}: permission denied ({exc})", permission_fix(pid)
                ) from exc
            if is_usb_error(exc, LIBUSB_BUSY, errno.EBUSY):
                raise CameraAccessError(f"{where}: interface busy ({exc})", BUSY_FIX) from exc
            raise CameraError(f"{where}: cannot open: {exc}") from exc
        except ValueError as exc:
            raise CameraAccessError(
                f"{where}: cannot read string descriptors ({exc})", permission_fix(pid)
            ) from exc
        if ep is None:
            usb.util.dispose_resources(dev)
            raise CameraError(f"{where}: no bulk IN endpoint 0x{_BULK_IN:02X} on interface 0")
        self._dev = dev
        self._max_packet = int(ep.wMaxPacketSize) or 512
        # Every read a multiple of the packet size: a read that ends inside a packet overflows.
        self._chunk = -(-self.settings.chunk_bytes // self._max_packet) * self._max_packet
        self.name = f"{KNOWN_PRODUCTS.get(pid, 'camera')} {serial}"
        try:
            status = self.status()
        except (usb.core.USBError, DeviceError) as exc:
            self._release()
            if is_usb_error(exc, LIBUSB_PIPE, errno.EPIPE):
                raise CameraError(
                    f"{self.name}: stalls our GET_STATUS request, so it does not speak the "
                    "toftwin USB wire protocol; a real pico flexx streams through royale "
                    "(drivers.camera.royale.RoyaleCamera)"
                ) from exc
            raise CameraError(f"{self.name}: GET_STATUS failed: {exc}") from exc
        if status.wire_version not in READABLE_VERSIONS:
            self._release()
            raise CameraError(
                f"{self.name}: device speaks wire version {status.wire_version}; this driver "
                f"speaks {', '.join(map(str, READABLE_VERSIONS))}"
            )
        self._identity = CameraIdentity(
            model=KNOWN_PRODUCTS.get(pid, f"PMD device {pid:04x}"),
            serial=serial,
            product=dev.product,
            manufacturer=dev.manufacturer,
            vendor_id=int(dev.idVendor),
            product_id=pid,
            firmware=status.firmware,
            usb_speed=USB_SPEEDS.get(dev.speed or 0, f"code {dev.speed}"),
            bus=dev.bus,
            address=dev.address,
            backend="pyusb",
            extra={"wire_version": str(status.wire_version), "usb_version": bcd(dev.bcdUSB)},
        )
        if status.streaming:  # left running by an earlier session
            self._ctrl_out(Request.STOP, 0, "STOP")
        uc = self._use_case
        self._ctrl_out(Request.SET_USE_CASE, uc.code, f"SET_USE_CASE({uc.name})")

    def _release(self) -> None:
        dev, self._dev = self._dev, None
        if dev is not None:
            with contextlib.suppress(usb.core.USBError):
                usb.util.release_interface(dev, INTERFACE)
            with contextlib.suppress(usb.core.USBError):
                usb.util.dispose_resources(dev)

    def _require(self) -> Any:
        if self._dev is None:
            self.connect()
        return self._dev

    def _gone(self, exc: BaseException) -> bool:
        """True if ``exc`` means the device went away (unplugged, reset)."""
        if is_usb_error(exc, LIBUSB_NO_DEVICE, errno.ENODEV):
            return True
        if isinstance(exc, usb.core.USBError) and exc.errno == errno.EIO:
            serial = self._identity.serial if self._identity is not None else None
            return self._find(serial) is None  # I/O error: gone if it left the bus
        return False

    def _reconnect(self, cause: BaseException) -> None:
        """Wait for the camera to come back, reopen it, restore use case and streaming."""
        self.stats.reconnects += 1
        was_streaming = self._streaming
        self._release()
        self._streaming = False
        self._expected_seq = None
        timeout = self.settings.reconnect_timeout_s
        deadline = time.monotonic() + timeout
        _log.warning("%s: device gone (%s); waiting up to %g s", self.name, cause, timeout)
        last: BaseException = cause
        serial = self._identity.serial if self._identity is not None else None
        while True:
            dev = self._find(serial)  # the same camera, not just any
            if dev is not None:
                try:
                    self._open(dev)
                    if was_streaming:
                        self.start()
                    _log.info("%s: reconnected", self.name)
                    return
                except CameraAccessError:
                    raise
                except (CameraError, usb.core.USBError) as exc:
                    last = exc  # came back but not ready yet: try again
                    self._release()
            if time.monotonic() >= deadline:
                raise DeviceDisconnectedError(
                    f"{self.name}: disconnected ({cause}) and not back within {timeout:g} s "
                    f"(last: {last})"
                ) from cause
            time.sleep(self.settings.reconnect_poll_s)

    # -- control requests ---------------------------------------------------------------------
    def _ctrl_out(self, request: int, value: int, what: str) -> None:
        dev = self._require()
        try:
            dev.ctrl_transfer(
                RequestType.OUT, request, value, 0, None, _ms(self.settings.ctrl_timeout_s)
            )
        except usb.core.USBError as exc:
            if is_usb_error(exc, LIBUSB_PIPE, errno.EPIPE):
                reason = ""
                with contextlib.suppress(DeviceError, usb.core.USBError):
                    reason = f": {self.status().last_error_text}"
                raise CameraError(f"{self.name}: device refused {what}{reason}") from exc
            raise

    def status(self) -> DeviceStatus:
        """Read GET_STATUS (wire version, use case, streaming, last error, next sequence)."""
        dev = self._require()
        data = dev.ctrl_transfer(
            RequestType.IN, Request.GET_STATUS, 0, 0, STATUS_SIZE, _ms(self.settings.ctrl_timeout_s)
        )
        return decode_status(bytes(data))

    def _with_reconnect(self, action: Any) -> Any:
        try:
            return action()
        except usb.core.USBError as exc:
            if not self._gone(exc):
                raise CameraError(f"{self.name}: USB error: {exc}") from exc
            self._reconnect(exc)
            return action()

    # -- the Camera protocol ------------------------------------------------------------------
    @property
    def use_case(self) -> UseCase:
        return self._use_case

    def configure(self, use_case: str | UseCase) -> None:
        """Select a use case; a running stream is stopped, reconfigured and restarted."""
        uc = get_use_case(use_case)
        self._require()
        was_streaming = self._streaming
        if was_streaming:
            self.stop()

        def send() -> None:
            self._ctrl_out(Request.SET_USE_CASE, uc.code, f"SET_USE_CASE({uc.name})")

        self._use_case = uc  # set first, so that a reconnect restores the new one
        self._with_reconnect(send)
        if was_streaming:
            self.start()

    def start(self) -> None:
        """Start streaming; the first frame after it sets the expected sequence number."""
        self._require()
        if self._streaming:
            return

        def send() -> None:
            self._ctrl_out(Request.START, 0, "START")

        self._with_reconnect(send)
        self._streaming = True
        self._expected_seq = None

    def stop(self) -> None:
        """Stop streaming; the device drops any frame in flight."""
        if self._dev is None or not self._streaming:
            self._streaming = False
            return
        self._streaming = False
        try:
            self._ctrl_out(Request.STOP, 0, "STOP")
        except usb.core.USBError as exc:
            if not self._gone(exc):
                raise CameraError(f"{self.name}: USB error on STOP: {exc}") from exc
            # unplugged: a replugged device comes back stopped; nothing to do now

    def identity(self) -> CameraIdentity:
        self._require()
        assert self._identity is not None
        return self._identity

    def capture(self, n: int = 1) -> list[RawFrame]:
        """The next ``n`` checked raw frames of the configured use case.

        Raises
        ------
        DeviceInputError
            ``n`` is not an integer >= 1.
        DeviceTimeoutError
            No frame started within ``read_timeout_s`` on ``1 + no_data_retries`` reads.
        FrameError
            ``on_bad_frame="raise"`` and a frame was bad or missing, or more than
            ``max_bad_frames`` bad frames in a row.
        DeviceDisconnectedError
            The camera was unplugged and did not come back within ``reconnect_timeout_s``.
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise DeviceInputError("n", f"got {n!r}; an integer >= 1 frames")
        self._require()
        one_shot = not self._streaming
        if one_shot:
            self.start()
        try:
            return self._capture(n)
        finally:
            if one_shot:
                try:
                    self.stop()
                except DeviceError as exc:  # do not mask the capture's own outcome
                    _log.warning("%s: stop after capture failed: %s", self.name, exc)

    def _capture(self, n: int) -> list[RawFrame]:
        frames: list[RawFrame] = []
        bad_in_row = 0
        timeouts_in_row = 0
        while len(frames) < n:
            try:
                data = self._read_transfer()
            except usb.core.USBTimeoutError:
                self.stats.timeouts += 1
                timeouts_in_row += 1
                if timeouts_in_row > self.settings.no_data_retries:
                    raise DeviceTimeoutError(
                        f"{self.name}: no frame within {self.settings.read_timeout_s:g} s on "
                        f"bulk IN 0x{_BULK_IN:02X} ({timeouts_in_row} reads; use case "
                        f"{self._use_case.name}, {len(frames)} of {n} frames received)"
                    ) from None
                continue
            except usb.core.USBError as exc:
                if not self._gone(exc):
                    raise CameraError(f"{self.name}: USB error reading a frame: {exc}") from exc
                self._reconnect(exc)
                if not self._streaming:
                    self.start()
                continue
            except FrameError as exc:  # truncated inside the transfer
                bad_in_row = self._bad_frame(exc, bad_in_row)
                continue
            timeouts_in_row = 0
            try:
                frame = self._check(data)
            except FrameError as exc:
                bad_in_row = self._bad_frame(exc, bad_in_row)
                continue
            bad_in_row = 0
            frames.append(frame)
        return frames

    def _read_transfer(self) -> bytes:
        """One frame: bulk reads of ``chunk`` bytes until a short (or zero-length) packet."""
        dev = self._dev
        limit = self._use_case.frame_bytes + self._max_packet
        parts: list[bytes] = []
        total = 0
        timeout = _ms(self.settings.read_timeout_s)
        while True:
            try:
                chunk = dev.read(_BULK_IN, self._chunk, timeout)
            except usb.core.USBTimeoutError:
                if not parts:
                    raise
                raise TruncatedFrameError(
                    "truncated",
                    f"{self.name}: transfer stalled after {total} bytes "
                    f"(timeout {self.settings.read_timeout_s:g} s)",
                ) from None
            parts.append(chunk.tobytes())
            total += len(chunk)
            if len(chunk) < self._chunk:
                return b"".join(parts)
            if total > limit:
                # Not a frame of this use case: read to the end of the transfer, then refuse it.
                while len(chunk) == self._chunk:
                    chunk = dev.read(_BULK_IN, self._chunk, timeout)
                raise FrameError(
                    "length",
                    f"{self.name}: transfer longer than {limit} bytes, the largest "
                    f"frame of use case {self._use_case.name}",
                )

    def _check(self, data: bytes) -> RawFrame:
        """Decode, check use case and sequence; count and return the RawFrame."""
        wf = decode_frame(data)
        h = wf.header
        if h.use_case_code != self._use_case.code:
            raise FrameError(
                "use-case",
                f"{self.name}: frame {h.sequence} is of use case "
                f"{get_use_case(h.use_case_code).name}, configured {self._use_case.name}",
                h.sequence,
            )
        expected = self._expected_seq
        self._expected_seq = (h.sequence + 1) % 2**32
        if expected is not None and h.sequence != expected:
            gap = (h.sequence - expected) % 2**32
            if gap >= 2**31:  # behind the expected number: repeated or reordered
                raise FrameError(
                    "sequence",
                    f"{self.name}: frame {h.sequence} arrived after frame {(expected - 1) % 2**32}",
                    h.sequence,
                )
            self.stats.dropped += gap
            message = (
                f"{self.name}: {gap} frame{'s' if gap > 1 else ''} dropped before frame "
                f"{h.sequence} (expected {expected})"
            )
            if self.settings.on_bad_frame == "raise":
                raise FrameDroppedError(message, h.sequence, gap)
            _log.warning("%s", message)
        self.stats.frames += 1
        return wire_to_raw_frame(wf, {"device": self.name, "backend": "pyusb"})

    def _bad_frame(self, exc: FrameError, bad_in_row: int) -> int:
        if exc.sequence is not None and exc.reason in _TRUSTED_SEQUENCE:
            # the frame arrived, if damaged: it is counted as bad, not again as dropped
            self._expected_seq = (exc.sequence + 1) % 2**32
        if isinstance(exc, TruncatedFrameError):
            self.stats.truncated += 1
        elif isinstance(exc, CorruptFrameError):
            self.stats.corrupt += 1
        else:
            self.stats.invalid += 1
        bad_in_row += 1
        if self.settings.on_bad_frame == "raise":
            raise exc
        if bad_in_row > self.settings.max_bad_frames:
            raise type(exc)(
                exc.reason,
                f"{exc} (gave up after {bad_in_row} bad frames in a row; stats "
                f"{self.stats.to_dict()})",
                exc.sequence,
            ) from exc
        _log.warning("%s: bad frame skipped: %s", self.name, exc)
        return bad_in_row
