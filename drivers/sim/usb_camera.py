"""Simulated pico flexx on USB: a pyusb backend that speaks our wire format.

:class:`UsbCameraSim` is a ``usb.backend.IBackend``: pass it to ``usb.core.find(backend=...)``
(or to :class:`drivers.camera.UsbCamera`) and the driver's normal pyusb code runs unchanged
against it - enumeration, device / configuration / interface / endpoint descriptors, string
descriptors over standard GET_DESCRIPTOR control requests, open / close, configuration, interface
claiming, kernel-driver queries, our vendor control requests and bulk IN reads, with libusb's
error codes (``USBError`` with ``backend_error_code`` and ``errno`` set as pyusb's libusb1
backend sets them).

The device presents 0x1C28:0xC012, product ``"pico flexx (simulated)"``, a serial number, one
configuration with one vendor-specific interface and a bulk IN endpoint 0x81 (512-byte packets,
high speed). Frames come from ``frame_source(CameraRequest) -> RawFrame`` (the renderer, later;
:func:`plane_source` for tests), are quantised to 12 bits and encoded with
:func:`drivers.camera.wire.encode_raw_frame`; every frame is one bulk transfer, delivered in
whole packets to reads of any multiple of the packet size and ended by a short packet (or a
zero-length packet when its length is a multiple of 512).

Timing: with ``instant=True`` a frame is produced as soon as the host reads; otherwise frames
are due at the use case's frame rate from START. Rendering time never counts against the host's
read timeout. State is evaluated lazily at each call; there is no background thread.

Faults (``name[:count][@skip]`` as for the serial simulators; see :data:`CAMERA_FAULTS`) are
armed at construction (``faults=["drop:1@2"]``) or at run time (``sim.inject("corrupt:1")``).
"""

from __future__ import annotations

import collections
import errno
import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import usb.backend
import usb.core

from drivers.camera.wire import (
    WIRE_VERSION,
    DeviceStatus,
    Request,
    RequestType,
    UseCase,
    encode_raw_frame,
    encode_status,
    get_use_case,
)
from drivers.errors import DeviceInputError
from drivers.sim.faults import CAMERA_FAULT_NAMES, FaultInjector, FaultSpec, parse_fault
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.raw import PHASE_OFFSETS_RAD, RawFrame

__all__ = [
    "CAMERA_FAULTS",
    "CameraFaultInjector",
    "CameraRequest",
    "FrameSource",
    "SimulatedUsbCamera",
    "UsbCameraSim",
    "parse_camera_fault",
    "plane_source",
]

PMD_VENDOR_ID = 0x1C28
PICO_FLEXX_PRODUCT_ID = 0xC012


# -- frame sources -------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraRequest:
    """What the simulated camera asks its frame source for.

    Attributes
    ----------
    use_case : UseCase
        Configured use case: frequencies, exposure, image size.
    frame_index : int
        Sequence number the frame will carry (frames since power-on, dropped ones included).
    seed : int
        The simulator's noise seed.
    timestamp_s : float
        Capture time, seconds since the epoch.
    rig_state : object or None
        Whatever the simulator's ``state_provider`` returns (``simulated_rig`` passes a
        :class:`drivers.rig.RigState` read from the simulated devices' physical state).
    """

    use_case: UseCase
    frame_index: int
    seed: int
    timestamp_s: float = 0.0
    rig_state: Any = None

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) the frame must have."""
        return self.use_case.shape

    def rng(self) -> np.random.Generator:
        """Generator seeded by ``(seed, frame_index)``: frame k is the same whenever drawn."""
        return np.random.default_rng([self.seed, self.frame_index])


FrameSource = Callable[[CameraRequest], RawFrame]


def plane_source(
    distance_m: float = 1.0,
    *,
    amplitude_dn: float = 400.0,
    intensity_dn: float = 900.0,
    noise_dn: float = 3.0,
) -> FrameSource:
    """A frame source for a fronto-parallel plane at a known radial distance on every pixel.

    Phase images ``C_i = a cos(tau_i + phi) + n`` with ``phi = 4 pi f d / c`` per modulation
    frequency (so :func:`sim_core.raw.reconstruct_raw` gives back ``distance_m``), intensity
    ``intensity_dn + n``, ``n`` Gaussian with standard deviation ``noise_dn`` from
    :meth:`CameraRequest.rng`.

    >>> src = plane_source(1.5, noise_dn=0.0)
    >>> frame = src(CameraRequest(get_use_case("MODE_5_45FPS_500"), 0, seed=1))
    >>> frame.phase_images.shape, float(frame.intensity[0, 0])
    ((1, 4, 171, 224), 900.0)
    """
    for name, value in (
        ("distance_m", distance_m),
        ("amplitude_dn", amplitude_dn),
        ("intensity_dn", intensity_dn),
        ("noise_dn", noise_dn),
    ):
        if not (math.isfinite(value) and value >= 0):
            raise DeviceInputError(name, f"got {value!r}; a finite number >= 0 is required")

    def source(request: CameraRequest) -> RawFrame:
        uc = request.use_case
        h, w = uc.shape
        rng = request.rng()
        freqs = np.asarray(uc.frequencies_hz, dtype=np.float64)
        phi = np.mod(4.0 * np.pi * freqs * distance_m / SPEED_OF_LIGHT_M_S, 2.0 * np.pi)
        ideal = amplitude_dn * np.cos(PHASE_OFFSETS_RAD[None, :] + phi[:, None])  # (n_f, 4)
        phases = np.broadcast_to(ideal[:, :, None, None], (len(freqs), 4, h, w))
        intensity = np.full((h, w), intensity_dn)
        if noise_dn > 0:
            phases = phases + noise_dn * rng.standard_normal(phases.shape)
            intensity = intensity + noise_dn * rng.standard_normal((h, w))
        return RawFrame(
            phase_images=np.asarray(phases, dtype=np.float32),
            intensity=intensity.astype(np.float32),
            frequencies_hz=freqs,
            saturated=np.zeros((h, w), dtype=bool),
            sbi_limit=np.zeros((h, w), dtype=bool),
            exposure_s=uc.exposure_s,
            timestamp_s=request.timestamp_s,
            meta={
                "source": "plane",
                "distance_m": distance_m,
                "seed": request.seed,
                "frame_index": request.frame_index,
            },
        )

    return source


# -- faults --------------------------------------------------------------------------------
#: Camera fault names, what each does, and what one event is.
CAMERA_FAULTS: dict[str, str] = {
    "no-data": "the bulk IN endpoint sends nothing: the host's read times out "
    "(event: a read that would start a frame)",
    "truncated": "the frame's transfer ends after half its bytes (event: a frame)",
    "corrupt": "payload bytes flipped after the CRC was computed (event: a frame)",
    "drop": "a frame is produced, its sequence number used, but never sent (event: a frame)",
    "disconnect": "the device leaves the bus for 'downtime_s' (default 0.3 s; inf: for good) "
    "and comes back with a new address in power-on state (event: a frame)",
}


def parse_camera_fault(text: str) -> FaultSpec:
    """Parse ``name[:count][@skip]`` for the camera (see :data:`CAMERA_FAULTS`).

    >>> parse_camera_fault("drop:2@3")
    FaultSpec(name='drop', count=2, skip=3, params={})
    """
    return parse_fault(text, CAMERA_FAULT_NAMES)


class CameraFaultInjector(FaultInjector):
    """Armed camera faults: the serial simulators' injector, restricted to camera faults."""

    def __init__(self, faults: Iterable[FaultSpec | str] = ()) -> None:
        super().__init__(list(faults), allowed=CAMERA_FAULT_NAMES)


# -- libusb error codes, as pyusb's libusb1 backend raises them ------------------------------
_ERRORS: dict[int, tuple[str, int]] = {
    -2: ("Invalid parameter", errno.EINVAL),
    -3: ("Access denied (insufficient permissions)", errno.EACCES),
    -4: ("No such device (it may have been disconnected)", errno.ENODEV),
    -5: ("Entity not found", errno.ENOENT),
    -6: ("Resource busy", errno.EBUSY),
    -7: ("Operation timed out", errno.ETIMEDOUT),
    -8: ("Overflow", errno.EOVERFLOW),
    -9: ("Pipe error", errno.EPIPE),
}
_INVALID_PARAM = -2
_ACCESS = -3
_NO_DEVICE = -4
_NOT_FOUND = -5
_BUSY = -6
_TIMEOUT = -7
_OVERFLOW = -8
_PIPE = -9


def _usb_error(code: int) -> usb.core.USBError:
    text, err = _ERRORS[code]
    cls = usb.core.USBTimeoutError if code == _TIMEOUT else usb.core.USBError
    return cls(text, code, err)


class _Descriptor:
    """A descriptor: the USB fields as attributes (what pyusb copies from a backend)."""

    def __init__(self, **fields: Any) -> None:
        self.__dict__.update(fields)


@dataclass
class _Handle:
    """An open device handle; dead once the device left the bus (``generation`` changed)."""

    device: SimulatedUsbCamera
    generation: int
    closed: bool = False


# -- the device model ----------------------------------------------------------------------
class SimulatedUsbCamera:
    """One simulated USB device: descriptors, control requests, the frame stream, faults.

    Parameters
    ----------
    frame_source : callable or None
        ``CameraRequest -> RawFrame``; :func:`plane_source` at 1 m when None.
    seed : int
        Noise seed handed to the source in every :class:`CameraRequest`.
    serial, product, manufacturer : str
        String descriptors.
    vendor_id, product_id : int
    bus, address : int
        Where it sits; every reconnect gives it the next address, as the host would.
    port_numbers : tuple of int
    speed : int
        libusb speed code (3 = high speed, 480 Mbit/s).
    usb_version, firmware_bcd : int
        ``bcdUSB`` and ``bcdDevice``.
    max_packet_size : int
        ``wMaxPacketSize`` of the bulk IN endpoint.
    instant : bool
        Produce frames as fast as the host reads (True) or at the use case's frame rate.
    faults : iterable of str or FaultSpec
        Armed at construction (see :data:`CAMERA_FAULTS`).
    state_provider : callable or None
        Called for every frame; its value goes to ``CameraRequest.rig_state``.
    access : {"ok", "denied"}
        ``"denied"``: opening fails with LIBUSB_ERROR_ACCESS (no udev rule).
    kernel_driver_active : bool
        A kernel driver is bound to interface 0: claiming fails with LIBUSB_ERROR_BUSY until it
        is detached.
    busy : bool
        Another process has claimed interface 0: claiming fails with LIBUSB_ERROR_BUSY.
    speaks_wire : bool
        False for a device that stalls our vendor requests (a real pico flexx, another device).
    """

    def __init__(
        self,
        frame_source: FrameSource | None = None,
        *,
        seed: int = 0,
        serial: str = "0005-4804-0050-1827",
        product: str = "pico flexx (simulated)",
        manufacturer: str = "pmdtechnologies ag (simulated)",
        vendor_id: int = PMD_VENDOR_ID,
        product_id: int = PICO_FLEXX_PRODUCT_ID,
        bus: int = 1,
        address: int = 4,
        port_numbers: tuple[int, ...] = (2,),
        speed: int = 3,
        usb_version: int = 0x0210,
        firmware_bcd: int = 0x0100,
        max_packet_size: int = 512,
        instant: bool = True,
        faults: Iterable[str | FaultSpec] = (),
        state_provider: Callable[[], Any] | None = None,
        access: str = "ok",
        kernel_driver_active: bool = False,
        busy: bool = False,
        speaks_wire: bool = True,
    ) -> None:
        if access not in ("ok", "denied"):
            raise DeviceInputError("access", f"got {access!r}; 'ok' or 'denied'")
        if max_packet_size not in (8, 16, 32, 64, 512, 1024):
            raise DeviceInputError(
                "max_packet_size", f"got {max_packet_size}; 8, 16, 32, 64, 512 or 1024"
            )
        self.frame_source = frame_source or plane_source()
        self.seed = int(seed)
        self.serial = serial
        self.product = product
        self.manufacturer = manufacturer
        self.vendor_id = vendor_id
        self.product_id = product_id
        self.bus = bus
        self.address = address
        self.port_numbers = port_numbers
        self.speed = speed
        self.usb_version = usb_version
        self.firmware_bcd = firmware_bcd
        self.max_packet_size = max_packet_size
        self.instant = instant
        self.faults = CameraFaultInjector(faults)
        self.state_provider = state_provider
        self.access = access
        self.kernel_driver_active = kernel_driver_active
        self.busy = busy
        self.speaks_wire = speaks_wire
        self._lock = threading.RLock()
        self.present = True
        self._replug_at: float | None = None
        self.generation = 0
        #: control requests received: (bmRequestType, bRequest, wValue, wIndex)
        self.transcript: collections.deque[tuple[int, int, int, int]] = collections.deque(
            maxlen=1000
        )
        self.frames_produced = 0
        self.frames_sent = 0
        self.disconnects = 0
        self._power_on()

    # -- state --------------------------------------------------------------------------------
    def _power_on(self) -> None:
        self.configuration = 1  # the host configures a device at enumeration
        self.claimed: set[int] = set()
        self.use_case: UseCase | None = None
        self.streaming = False
        self.sequence = 0
        self.last_error = 0
        self._epoch = 0
        self._transfer: bytes | None = None
        self._offset = 0
        self._pending_zlp = False
        self._stream_t0 = 0.0
        self._stream_k = 0

    def _update(self) -> None:
        """Bring a device whose downtime is over back onto the bus."""
        if not self.present and self._replug_at is not None and time.monotonic() >= self._replug_at:
            self.present = True
            self._replug_at = None
            self.address += 1
            self._power_on()

    def is_present(self) -> bool:
        """On the bus now (a device whose downtime is over comes back here)."""
        with self._lock:
            self._update()
            return self.present

    def unplug(self, downtime_s: float = math.inf) -> None:
        """Leave the bus now; come back after ``downtime_s`` (never when infinite)."""
        with self._lock:
            self.present = False
            self.generation += 1
            self.disconnects += 1
            self._replug_at = None if math.isinf(downtime_s) else time.monotonic() + downtime_s
            self.streaming = False
            self._transfer = None

    def plug(self) -> None:
        """Come back onto the bus now (new address, power-on state)."""
        with self._lock:
            if not self.present:
                self._replug_at = time.monotonic()
                self._update()

    def inject(self, fault: str | FaultSpec, **params: float) -> FaultSpec:
        """Arm a fault at run time (``"truncated:1"``, ``"disconnect:1"`` with downtime_s=...)."""
        return self.faults.inject(fault, **params)

    def status(self) -> DeviceStatus:
        """What GET_STATUS answers now."""
        uc = self.use_case
        return DeviceStatus(
            wire_version=WIRE_VERSION,
            use_case_code=uc.code if uc else 0,
            streaming=self.streaming,
            last_error=self.last_error,
            width=uc.width if uc else 0,
            height=uc.height if uc else 0,
            next_sequence=self.sequence,
            firmware_bcd=self.firmware_bcd,
        )

    # -- descriptors --------------------------------------------------------------------------
    def device_descriptor(self) -> _Descriptor:
        with self._lock:
            self._update()
            return _Descriptor(
                bLength=18,
                bDescriptorType=1,
                bcdUSB=self.usb_version,
                bDeviceClass=0,
                bDeviceSubClass=0,
                bDeviceProtocol=0,
                bMaxPacketSize0=64,
                idVendor=self.vendor_id,
                idProduct=self.product_id,
                bcdDevice=self.firmware_bcd,
                iManufacturer=1,
                iProduct=2,
                iSerialNumber=3,
                bNumConfigurations=1,
                address=self.address,
                bus=self.bus,
                port_number=self.port_numbers[-1],
                port_numbers=self.port_numbers,
                speed=self.speed,
            )

    @staticmethod
    def configuration_descriptor() -> _Descriptor:
        return _Descriptor(
            bLength=9,
            bDescriptorType=2,
            wTotalLength=9 + 9 + 7,
            bNumInterfaces=1,
            bConfigurationValue=1,
            iConfiguration=0,
            bmAttributes=0x80,
            bMaxPower=250,
            extra_descriptors=[],
        )

    @staticmethod
    def interface_descriptor() -> _Descriptor:
        return _Descriptor(
            bLength=9,
            bDescriptorType=4,
            bInterfaceNumber=0,
            bAlternateSetting=0,
            bNumEndpoints=1,
            bInterfaceClass=0xFF,
            bInterfaceSubClass=0,
            bInterfaceProtocol=0,
            iInterface=0,
            extra_descriptors=[],
        )

    def endpoint_descriptor(self) -> _Descriptor:
        return _Descriptor(
            bLength=7,
            bDescriptorType=5,
            bEndpointAddress=0x81,
            bmAttributes=0x02,
            wMaxPacketSize=self.max_packet_size,
            bInterval=0,
            bRefresh=0,
            bSynchAddress=0,
            extra_descriptors=[],
        )

    def _string(self, index: int) -> bytes | None:
        if index == 0:
            return bytes([4, 3, 0x09, 0x04])  # LANGID 0x0409, US English
        text = {1: self.manufacturer, 2: self.product, 3: self.serial}.get(index)
        if text is None:
            return None
        body = text.encode("utf-16-le")
        return bytes([2 + len(body), 3]) + body

    # -- handles ------------------------------------------------------------------------------
    def open(self) -> _Handle:
        with self._lock:
            self._update()
            if not self.present:
                raise _usb_error(_NO_DEVICE)
            if self.access == "denied":
                raise _usb_error(_ACCESS)
            return _Handle(self, self.generation)

    def _alive(self, handle: _Handle) -> None:
        """Raise LIBUSB_ERROR_NO_DEVICE if the handle's device left the bus since it opened."""
        self._update()
        if handle.closed or handle.generation != self.generation or not self.present:
            raise _usb_error(_NO_DEVICE)

    def set_configuration(self, handle: _Handle, value: int) -> None:
        with self._lock:
            self._alive(handle)
            if value not in (0, 1):
                raise _usb_error(_NOT_FOUND)
            if self.claimed:
                raise _usb_error(_BUSY)
            self.configuration = value

    def get_configuration(self, handle: _Handle) -> int:
        with self._lock:
            self._alive(handle)
            return self.configuration

    def claim(self, handle: _Handle, intf: int) -> None:
        with self._lock:
            self._alive(handle)
            if intf != 0 or self.configuration != 1:
                raise _usb_error(_NOT_FOUND)
            if self.busy or self.kernel_driver_active:
                raise _usb_error(_BUSY)
            self.claimed.add(intf)

    def release(self, handle: _Handle, intf: int) -> None:
        with self._lock:
            self._alive(handle)
            self.claimed.discard(intf)

    def kernel_driver(self, handle: _Handle, intf: int, detach: bool | None = None) -> bool:
        with self._lock:
            self._alive(handle)
            if intf != 0:
                raise _usb_error(_NOT_FOUND)
            if detach is True:
                if not self.kernel_driver_active:
                    raise _usb_error(_NOT_FOUND)
                self.kernel_driver_active = False
            elif detach is False:
                self.kernel_driver_active = True
            return self.kernel_driver_active

    # -- control requests ---------------------------------------------------------------------
    def control(
        self, handle: _Handle, request_type: int, request: int, value: int, index: int, data: Any
    ) -> int:
        with self._lock:
            self._alive(handle)
            self.transcript.append((request_type, request, value, index))
            if request_type == 0x80 and request == 0x06:  # standard GET_DESCRIPTOR
                desc = self._string(value & 0xFF) if value >> 8 == 3 else None
                if desc is None:
                    raise _usb_error(_PIPE)
                return _fill(data, desc)
            if request_type == RequestType.OUT and self.speaks_wire:
                self._vendor_out(request, value)
                return 0
            if (request_type == RequestType.IN and self.speaks_wire
                    and request == Request.GET_STATUS):
                return _fill(data, encode_status(self.status()))
            if request_type in (RequestType.IN, RequestType.OUT) and self.speaks_wire:
                self.last_error = 1
            raise _usb_error(_PIPE)  # a stall: request not supported

    def _vendor_out(self, request: int, value: int) -> None:
        def refuse(code: int) -> None:
            self.last_error = code
            raise _usb_error(_PIPE)

        if request == Request.SET_USE_CASE:
            if self.streaming:
                refuse(3)
            try:
                self.use_case = get_use_case(value)
            except DeviceInputError:
                refuse(2)
        elif request == Request.START:
            if self.use_case is None:
                refuse(4)
            if not self.streaming:
                self.streaming = True
                self._epoch += 1
                self._stream_t0 = time.monotonic()
                self._stream_k = 0
        elif request == Request.STOP:
            self.streaming = False
            self._epoch += 1
            self._transfer = None
            self._pending_zlp = False
        else:
            refuse(1)
        self.last_error = 0

    # -- the stream ---------------------------------------------------------------------------
    def bulk_read(self, handle: _Handle, endpoint: int, buff: Any, timeout_ms: int) -> int:
        """Deliver the next packets of the current frame transfer (see the module doc)."""
        deadline = math.inf if timeout_ms <= 0 else time.monotonic() + timeout_ms / 1000.0
        silent = False  # a 'no-data' fault fired: nothing comes until the host gives up
        while True:
            job = None
            with self._lock:
                self._alive(handle)
                if endpoint != 0x81:
                    raise _usb_error(_INVALID_PARAM)
                if 0 not in self.claimed:
                    raise _usb_error(_NOT_FOUND)
                if self._pending_zlp:
                    self._pending_zlp = False
                    return 0
                if self._transfer is not None:
                    return self._serve(buff)
                wait_until = deadline
                if self.streaming and not silent:
                    assert self.use_case is not None
                    silent = self.faults.fire("no-data") is not None
                    due = self._stream_t0 + self._stream_k / self.use_case.frame_rate_hz
                    if silent:
                        pass
                    elif self.instant or time.monotonic() >= due:
                        job = self._next_job()
                        if job is None:
                            continue  # dropped: the next frame follows
                    else:
                        wait_until = min(due, deadline)
            if job is not None:
                self._produce(*job)
                continue
            now = time.monotonic()
            if now >= deadline:
                raise _usb_error(_TIMEOUT)
            # sleep in short slices so that a STOP, an unplug or a due frame is seen promptly
            time.sleep(max(0.0, min(wait_until, now + 0.05) - now))
            if time.monotonic() >= deadline:
                raise _usb_error(_TIMEOUT)

    def _next_job(self) -> tuple[int, int, UseCase, int] | None:
        """Take the next sequence number (with the lock held); apply drop / disconnect."""
        assert self.use_case is not None
        seq = self.sequence
        self.sequence = (self.sequence + 1) % 2**32
        self._stream_k += 1
        self.frames_produced += 1
        if self.faults.fire("drop") is not None:
            return None
        spec = self.faults.fire("disconnect")
        if spec is not None:
            self.unplug(float(spec.params.get("downtime_s", 0.3)))
            raise _usb_error(_NO_DEVICE)
        return (self._epoch, self.generation, self.use_case, seq)

    def _produce(self, epoch: int, generation: int, uc: UseCase, seq: int) -> None:
        """Render (without the lock: a renderer may be slow), encode, apply byte faults."""
        now_s = time.time()
        state = self.state_provider() if self.state_provider is not None else None
        request = CameraRequest(uc, seq, self.seed, now_s, state)
        raw = self.frame_source(request)
        if raw.shape != uc.shape or raw.phase_images.shape != (uc.n_frequencies, 4, *uc.shape):
            raise DeviceInputError(
                "frame_source",
                f"returned phase images {raw.phase_images.shape} and intensity "
                f"{raw.shape} for {request!r}; expected ({uc.n_frequencies}, 4, {uc.height}, "
                f"{uc.width}) and {uc.shape}",
            )
        # the frame's reported illumination temperature travels in the header (wire version 2);
        # its time is the frame source's (a world on the lab's clock stamps its own), or now
        stamp_s = raw.timestamp_s if raw.timestamp_s > 0.0 else now_s
        data = encode_raw_frame(raw, use_case=uc, sequence=seq, timestamp_us=int(stamp_s * 1e6))
        if self.faults.fire("corrupt") is not None:
            buf = bytearray(data)
            for k in range(64 + 7, len(buf), max(1, len(buf) // 7)):
                buf[k] ^= 0x5A
            data = bytes(buf)
        if self.faults.fire("truncated") is not None:
            data = data[: len(data) // 2]
        with self._lock:
            if self.streaming and self._epoch == epoch and self.generation == generation:
                self._transfer = data
                self._offset = 0
                self.frames_sent += 1

    def _serve(self, buff: Any) -> int:
        """Copy whole packets of the current transfer into ``buff`` (lock held)."""
        assert self._transfer is not None
        size = len(buff) * buff.itemsize
        mps = self.max_packet_size
        remaining = len(self._transfer) - self._offset
        n = min(size, remaining)
        if n < remaining and size % mps != 0:
            # the device's next packet does not fit the host's buffer (libusb: babble)
            self._transfer = None
            raise _usb_error(_OVERFLOW)
        memoryview(buff).cast("B")[:n] = self._transfer[self._offset : self._offset + n]
        self._offset += n
        if self._offset == len(self._transfer):
            self._pending_zlp = n == size and len(self._transfer) % mps == 0
            self._transfer = None
        return n


def _fill(data: Any, payload: bytes) -> int:
    """Copy an IN control reply into the host's buffer, cut to its length (wLength)."""
    n = min(len(data) * data.itemsize, len(payload))
    memoryview(data).cast("B")[:n] = payload[:n]
    return n


# -- the pyusb backend -----------------------------------------------------------------------
class UsbCameraSim(usb.backend.IBackend):
    """A pyusb backend with one simulated pico flexx on its bus (more with :meth:`add_device`).

    Parameters are those of :class:`SimulatedUsbCamera` for the first device.

    Examples
    --------
    >>> import usb.core
    >>> sim = UsbCameraSim(plane_source(2.0), seed=7)
    >>> dev = usb.core.find(backend=sim, idVendor=0x1C28, idProduct=0xC012)
    >>> dev.product, dev.serial_number
    ('pico flexx (simulated)', '0005-4804-0050-1827')
    """

    def __init__(self, frame_source: FrameSource | None = None, **device: Any) -> None:
        super().__init__()
        self.devices: list[SimulatedUsbCamera] = []
        self.add_device(frame_source, **device)

    def add_device(
        self, frame_source: FrameSource | None = None, **device: Any
    ) -> SimulatedUsbCamera:
        """Put another simulated device on the bus and return it."""
        model = SimulatedUsbCamera(frame_source, **device)
        self.devices.append(model)
        return model

    @property
    def device(self) -> SimulatedUsbCamera:
        """The first device (the camera of the single-device case)."""
        return self.devices[0]

    def inject(self, fault: str | FaultSpec, **params: float) -> FaultSpec:
        """Arm a fault on the first device."""
        return self.device.inject(fault, **params)

    def unplug(self, downtime_s: float = math.inf) -> None:
        """Unplug the first device (see :meth:`SimulatedUsbCamera.unplug`)."""
        self.device.unplug(downtime_s)

    def plug(self) -> None:
        self.device.plug()

    # -- IBackend -----------------------------------------------------------------------------
    def enumerate_devices(self) -> list[SimulatedUsbCamera]:
        return [d for d in self.devices if d.is_present()]

    def get_parent(self, dev: SimulatedUsbCamera) -> None:
        return None

    def get_device_descriptor(self, dev: SimulatedUsbCamera) -> _Descriptor:
        return dev.device_descriptor()

    def get_configuration_descriptor(self, dev: SimulatedUsbCamera, config: int) -> _Descriptor:
        if config != 0:
            raise IndexError(f"invalid configuration index {config}")
        return dev.configuration_descriptor()

    def get_interface_descriptor(
        self, dev: SimulatedUsbCamera, intf: int, alt: int, config: int
    ) -> _Descriptor:
        if config != 0 or intf != 0 or alt != 0:
            raise IndexError(f"invalid interface index {intf} / alternate setting {alt}")
        return dev.interface_descriptor()

    def get_endpoint_descriptor(
        self, dev: SimulatedUsbCamera, ep: int, intf: int, alt: int, config: int
    ) -> _Descriptor:
        if config != 0 or intf != 0 or alt != 0 or ep != 0:
            raise IndexError(f"invalid endpoint index {ep}")
        return dev.endpoint_descriptor()

    def open_device(self, dev: SimulatedUsbCamera) -> _Handle:
        return dev.open()

    def close_device(self, dev_handle: _Handle) -> None:
        dev_handle.closed = True  # libusb_close never fails, even for an unplugged device

    def set_configuration(self, dev_handle: _Handle, config_value: int) -> None:
        dev_handle.device.set_configuration(dev_handle, config_value)

    def get_configuration(self, dev_handle: _Handle) -> int:
        return dev_handle.device.get_configuration(dev_handle)

    def set_interface_altsetting(self, dev_handle: _Handle, intf: int, altsetting: int) -> None:
        if intf != 0 or altsetting != 0:
            raise _usb_error(_NOT_FOUND)

    def claim_interface(self, dev_handle: _Handle, intf: int) -> None:
        dev_handle.device.claim(dev_handle, intf)

    def release_interface(self, dev_handle: _Handle, intf: int) -> None:
        dev_handle.device.release(dev_handle, intf)

    def bulk_read(self, dev_handle: _Handle, ep: int, intf: int, buff: Any, timeout: int) -> int:
        return dev_handle.device.bulk_read(dev_handle, ep, buff, timeout)

    def bulk_write(self, dev_handle: _Handle, ep: int, intf: int, data: Any, timeout: int) -> int:
        raise _usb_error(_INVALID_PARAM)  # the device has no OUT endpoint

    def ctrl_transfer(
        self,
        dev_handle: _Handle,
        bmRequestType: int,
        bRequest: int,
        wValue: int,
        wIndex: int,
        data: Any,
        timeout: int,
    ) -> int:
        return dev_handle.device.control(dev_handle, bmRequestType, bRequest, wValue, wIndex, data)

    def clear_halt(self, dev_handle: _Handle, ep: int) -> None:
        dev_handle.device._alive(dev_handle)

    def reset_device(self, dev_handle: _Handle) -> None:
        """A port reset: the device re-enumerates at once in power-on state."""
        dev = dev_handle.device
        dev._alive(dev_handle)
        dev.unplug(0.0)

    def is_kernel_driver_active(self, dev_handle: _Handle, intf: int) -> bool:
        return dev_handle.device.kernel_driver(dev_handle, intf)

    def detach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        dev_handle.device.kernel_driver(dev_handle, intf, detach=True)

    def attach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        dev_handle.device.kernel_driver(dev_handle, intf, detach=False)
