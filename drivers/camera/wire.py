"""Our USB wire format for raw ToF frames: pure encode / decode functions, no I/O.

A device speaking this format (the simulator :mod:`drivers.sim.usb_camera`, or a bridge firmware)
is driven by vendor control requests and sends every raw frame as one bulk IN transfer: a 64-byte
header followed by the images as little-endian ``uint16`` words holding 12-bit values. The byte
layout is documented in ``docs/devices.md`` ("Camera (USB)"); this module is its executable form.

Conventions
-----------
- A raw phase value ``r`` (12-bit unsigned, 0..4095) is the signed correlation value
  ``C = r - 2048`` DN (:data:`RAW_OFFSET`); :class:`~sim_core.raw.RawFrame` holds ``C`` as float32.
- The grey image is carried as its raw value and becomes ``RawFrame.intensity`` unchanged (DN).
- A pixel whose raw value sits at either end of the ADC range (0 or 4095) in any phase image, or
  at 4095 in the grey image, is marked ``saturated``; the wire carries no SBI flag, so
  ``sbi_limit`` is all False.
- CRC32 is the IEEE 802.3 CRC of :func:`zlib.crc32` (the one of Ethernet, PNG and gzip).

Everything here is a pure function over bytes and numpy arrays; the errors are
:class:`FrameError` subclasses (a :class:`~drivers.errors.ProtocolError`) naming what is wrong.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import zlib
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from drivers.errors import DeviceInputError, ProtocolError
from sim_core.raw import RawFrame

__all__ = [
    "BITS_PER_VALUE",
    "FLAG_GREY",
    "HEADER",
    "HEADER_SIZE",
    "MAGIC",
    "MAX_RAW",
    "N_PHASES",
    "RAW_OFFSET",
    "READABLE_VERSIONS",
    "STATUS",
    "STATUS_ERRORS",
    "STATUS_SIZE",
    "USE_CASES",
    "WIRE_VERSION",
    "CorruptFrameError",
    "DeviceStatus",
    "FrameError",
    "FrameHeader",
    "Request",
    "RequestType",
    "TruncatedFrameError",
    "UseCase",
    "WireFrame",
    "decode_frame",
    "decode_header",
    "decode_status",
    "encode_frame",
    "encode_raw_frame",
    "encode_status",
    "get_use_case",
    "quantize_frame",
    "raw_to_wire_values",
    "wire_to_raw_frame",
]

MAGIC = b"TOFW"
WIRE_VERSION = 2
#: versions this decoder reads: 1 (no temperature: its reserved bytes are zero) and 2
READABLE_VERSIONS = (1, 2)
HEADER_SIZE = 64
N_PHASES = 4
BITS_PER_VALUE = 12
MAX_RAW = (1 << BITS_PER_VALUE) - 1  # 4095
#: raw value of a zero correlation: C = raw - RAW_OFFSET (our convention, 2**11)
RAW_OFFSET = 1 << (BITS_PER_VALUE - 1)
#: header flag bit 0: the payload starts with a grey image (always set in version 1)
FLAG_GREY = 0x0001

#: Frame header, little-endian, 64 bytes (see docs/devices.md for the table):
#: magic, version, header size, flags, sequence, use case code, n frequencies, n phases,
#: bits per value, width, height, exposure [us], timestamp [us since the epoch],
#: frequency 0 [Hz], frequency 1 [Hz], payload length [bytes], payload CRC32,
#: illumination temperature [degC] as float32 (version 2; NaN: not reported; version 1 has
#: reserved zero bytes there), 8 reserved bytes, header CRC32 (over bytes 0..59).
HEADER = struct.Struct("<4sBBHIBBBBHHIQIIIIf8xI")
assert HEADER.size == HEADER_SIZE

# -- control requests ----------------------------------------------------------------------
class RequestType(IntEnum):
    """bmRequestType of our vendor requests: vendor, recipient device, OUT / IN."""

    OUT = 0x40
    IN = 0xC0


class Request(IntEnum):
    """bRequest of our vendor requests."""

    SET_USE_CASE = 0x01  # OUT, wValue = use case code, no data
    START = 0x02  # OUT, start streaming
    STOP = 0x03  # OUT, stop streaming, drop any frame in flight
    GET_STATUS = 0x10  # IN, wLength = 16


#: GET_STATUS reply: wire version, use case code (0 = none), streaming, last error, width,
#: height, next sequence number, firmware version (BCD), 2 reserved bytes.
STATUS = struct.Struct("<BBBBHHIH2x")
STATUS_SIZE = STATUS.size
assert STATUS_SIZE == 16

#: ``last_error`` codes of GET_STATUS: why the device stalled the last request.
STATUS_ERRORS: dict[int, str] = {
    0: "no error",
    1: "unknown request",
    2: "unknown use case code",
    3: "busy: not allowed while streaming",
    4: "no use case configured",
}


# -- use cases -----------------------------------------------------------------------------
@dataclass(frozen=True)
class UseCase:
    """A royale use case of the pico flexx as the twin knows it.

    Attributes
    ----------
    name : str
        Royale's name, e.g. ``"MODE_5_45FPS_500"``.
    code : int
        Our wire code (1..255; 0 means "none").
    frequencies_hz : tuple of float
        Modulation frequencies in the order of the raw frames (4 phase images each).
    exposure_s : float
        Exposure per phase step (the number at the end of the name, in microseconds).
    frame_rate_hz : float
        Depth frames per second.
    width, height : int
        Image size in pixels.
    """

    name: str
    code: int
    frequencies_hz: tuple[float, ...]
    exposure_s: float
    frame_rate_hz: float
    width: int = 224
    height: int = 171

    @property
    def n_frequencies(self) -> int:
        return len(self.frequencies_hz)

    @property
    def n_raw_frames(self) -> int:
        """Grey image plus four phase images per frequency (5 or 9)."""
        return 1 + N_PHASES * self.n_frequencies

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the images."""
        return (self.height, self.width)

    @property
    def payload_bytes(self) -> int:
        return self.n_raw_frames * self.width * self.height * 2

    @property
    def frame_bytes(self) -> int:
        """Header plus payload: the length of one bulk transfer."""
        return HEADER_SIZE + self.payload_bytes

    @property
    def exposure_us(self) -> int:
        return round(self.exposure_s * 1e6)


#: The two use cases the twin supports, by royale name.
USE_CASES: dict[str, UseCase] = {
    "MODE_5_45FPS_500": UseCase("MODE_5_45FPS_500", 1, (60.24e6,), 500e-6, 45.0),
    "MODE_9_5FPS_2000": UseCase("MODE_9_5FPS_2000", 2, (80.32e6, 60.24e6), 2000e-6, 5.0),
}
_BY_CODE = {uc.code: uc for uc in USE_CASES.values()}


def get_use_case(value: str | int | UseCase) -> UseCase:
    """Look a use case up by royale name, wire code or instance.

    >>> get_use_case("MODE_9_5FPS_2000").frequencies_hz
    (80320000.0, 60240000.0)
    >>> get_use_case(1).name
    'MODE_5_45FPS_500'
    """
    if isinstance(value, UseCase):
        return value
    if isinstance(value, str) and value in USE_CASES:
        return USE_CASES[value]
    if isinstance(value, int) and not isinstance(value, bool) and value in _BY_CODE:
        return _BY_CODE[value]
    raise DeviceInputError(
        "use_case",
        f"got {value!r}; one of {', '.join(USE_CASES)} (wire codes "
        f"{', '.join(str(uc.code) for uc in USE_CASES.values())})",
    )


# -- errors --------------------------------------------------------------------------------
class FrameError(ProtocolError):
    """A frame on the wire is not valid.

    Attributes
    ----------
    reason : str
        Short machine-readable cause: ``"short-header"``, ``"magic"``, ``"version"``,
        ``"header-size"``, ``"header-crc"``, ``"header"``, ``"length"``, ``"truncated"``,
        ``"payload-crc"``, ``"values"``, ``"sequence"``, ``"dropped"``, ``"use-case"``.
    sequence : int or None
        Sequence number from the header when it could be read.
    """

    def __init__(self, reason: str, message: str, sequence: int | None = None) -> None:
        self.reason = reason
        self.sequence = sequence
        super().__init__(message)


class TruncatedFrameError(FrameError):
    """Fewer bytes arrived than the header announces (or not even a whole header)."""


class CorruptFrameError(FrameError):
    """A CRC does not match: bytes changed on the way."""


# -- header --------------------------------------------------------------------------------
@dataclass(frozen=True)
class FrameHeader:
    """The decoded 64-byte header of one frame (every field of the wire table)."""

    sequence: int
    use_case_code: int
    n_frequencies: int
    width: int
    height: int
    exposure_us: int
    timestamp_us: int
    frequencies_hz: tuple[int, ...]
    payload_length: int
    payload_crc32: int
    version: int = WIRE_VERSION
    flags: int = FLAG_GREY
    n_phases: int = N_PHASES
    bits_per_value: int = BITS_PER_VALUE
    #: the illumination's temperature the camera reports with the frame [degC] (version 2)
    illumination_temperature_c: float | None = None

    @property
    def n_images(self) -> int:
        """Images in the payload: grey plus ``n_phases`` per frequency."""
        return 1 + self.n_phases * self.n_frequencies

    @property
    def expected_payload_length(self) -> int:
        return self.n_images * self.width * self.height * 2

    @property
    def use_case(self) -> UseCase:
        return get_use_case(self.use_case_code)


def _pack_header(h: FrameHeader) -> bytes:
    freqs = [*h.frequencies_hz, 0, 0][:2]
    body = HEADER.pack(
        MAGIC,
        h.version,
        HEADER_SIZE,
        h.flags,
        h.sequence,
        h.use_case_code,
        h.n_frequencies,
        h.n_phases,
        h.bits_per_value,
        h.width,
        h.height,
        h.exposure_us,
        h.timestamp_us,
        freqs[0],
        freqs[1],
        h.payload_length,
        h.payload_crc32,
        _temperature_field(h),
        0,
    )
    return body[:-4] + struct.pack("<I", zlib.crc32(body[:-4]))


def _temperature_field(h: FrameHeader) -> float:
    """The header's temperature field: the reported temperature, NaN when there is none (a
    version-1 header keeps its reserved zero bytes)."""
    if h.version < 2:
        return 0.0
    t = h.illumination_temperature_c
    return math.nan if t is None else float(t)


def decode_header(data: bytes) -> FrameHeader:
    """Decode and check the first 64 bytes of a frame.

    Raises
    ------
    TruncatedFrameError
        Fewer than 64 bytes.
    FrameError
        Wrong magic, version, header size or an impossible field (``reason`` says which).
    CorruptFrameError
        The header CRC does not match.
    """
    if len(data) < HEADER_SIZE:
        raise TruncatedFrameError(
            "short-header",
            f"frame of {len(data)} bytes is shorter than the {HEADER_SIZE}-byte header",
        )
    raw = bytes(data[:HEADER_SIZE])
    (
        magic,
        version,
        header_size,
        flags,
        seq,
        code,
        n_f,
        n_ph,
        bits,
        width,
        height,
        exp_us,
        stamp_us,
        f0,
        f1,
        length,
        payload_crc,
        temperature_c,
        header_crc,
    ) = HEADER.unpack(raw)
    if magic != MAGIC:
        raise FrameError("magic", f"frame starts with {magic!r}, expected {MAGIC!r}")
    if version not in READABLE_VERSIONS:
        raise FrameError(
            "version",
            f"frame has wire version {version}; this decoder reads {list(READABLE_VERSIONS)}",
            seq,
        )
    if header_size != HEADER_SIZE:
        raise FrameError(
            "header-size", f"header size field is {header_size}, expected {HEADER_SIZE}", seq
        )
    crc = zlib.crc32(raw[:-4])
    if crc != header_crc:
        raise CorruptFrameError(
            "header-crc",
            f"header CRC32 0x{header_crc:08X} does not match the header bytes "
            f"(computed 0x{crc:08X}); frame sequence field reads {seq}",
            seq,
        )
    problems = []
    if flags != FLAG_GREY:
        problems.append(f"flags 0x{flags:04X} (expected 0x{FLAG_GREY:04X})")
    if n_ph != N_PHASES:
        problems.append(f"n_phases {n_ph} (expected {N_PHASES})")
    if bits != BITS_PER_VALUE:
        problems.append(f"bits_per_value {bits} (expected {BITS_PER_VALUE})")
    if n_f not in (1, 2):
        problems.append(f"n_frequencies {n_f} (expected 1 or 2)")
    if width == 0 or height == 0:
        problems.append(f"image size {width} x {height}")
    freqs = (f0, f1)[: n_f if n_f in (1, 2) else 0]
    if any(f == 0 for f in freqs) or (n_f == 1 and f1 != 0):
        problems.append(f"frequencies ({f0}, {f1}) Hz for {n_f} frequencies")
    if code not in _BY_CODE:
        problems.append(f"use case code {code} (known: {sorted(_BY_CODE)})")
    elif _BY_CODE[code].n_frequencies != n_f:
        problems.append(f"use case {_BY_CODE[code].name} with {n_f} frequencies")
    if problems:
        raise FrameError("header", "invalid header: " + "; ".join(problems), seq)
    header = FrameHeader(
        sequence=seq,
        use_case_code=code,
        n_frequencies=n_f,
        width=width,
        height=height,
        exposure_us=exp_us,
        timestamp_us=stamp_us,
        frequencies_hz=freqs,
        payload_length=length,
        payload_crc32=payload_crc,
        version=version,
        flags=flags,
        n_phases=n_ph,
        bits_per_value=bits,
        illumination_temperature_c=(
            float(temperature_c) if version >= 2 and math.isfinite(temperature_c) else None),
    )
    if length != header.expected_payload_length:
        raise FrameError(
            "length",
            f"payload length field {length} bytes does not match {header.n_images} "
            f"images of {width} x {height} uint16 ({header.expected_payload_length} bytes)",
            seq,
        )
    return header


# -- frames --------------------------------------------------------------------------------
@dataclass(frozen=True)
class WireFrame:
    """One decoded frame: the header and the raw 12-bit images.

    Attributes
    ----------
    header : FrameHeader
    grey : (H, W) uint16
    phases : (n_f, 4, H, W) uint16
    """

    header: FrameHeader
    grey: np.ndarray = field(repr=False)
    phases: np.ndarray = field(repr=False)


def encode_frame(
    grey: np.ndarray,
    phases: np.ndarray,
    *,
    use_case: str | int | UseCase,
    sequence: int,
    timestamp_us: int,
    exposure_us: int | None = None,
    illumination_temperature_c: float | None = None,
) -> bytes:
    """Header plus payload of one frame from raw 12-bit images.

    Parameters
    ----------
    grey : (H, W) uint16
    phases : (n_f, 4, H, W) uint16
        Values 0..4095; ``n_f`` and the image size must match ``use_case``.
    use_case : name, code or UseCase
    sequence : int
        Frame counter, 0 .. 2**32-1.
    timestamp_us : int
        Capture time in microseconds since the Unix epoch.
    exposure_us : int or None
        Exposure per phase step; the use case's when None.
    illumination_temperature_c : float or None
        The illumination's temperature to report [degC]; None: not reported.
    """
    uc = get_use_case(use_case)
    grey = np.asarray(grey)
    phases = np.asarray(phases)
    expected = (uc.n_frequencies, N_PHASES, *uc.shape)
    if grey.shape != uc.shape or phases.shape != expected:
        raise DeviceInputError(
            "frame",
            f"grey {grey.shape} and phases {phases.shape} do not match use case "
            f"{uc.name}: grey {uc.shape}, phases {expected}",
        )
    for name, arr in (("grey", grey), ("phases", phases)):
        if arr.dtype != np.uint16:
            raise DeviceInputError(f"frame.{name}", f"dtype {arr.dtype}; uint16 expected")
        if arr.size and int(arr.max()) > MAX_RAW:
            raise DeviceInputError(
                f"frame.{name}", f"maximum {int(arr.max())} exceeds the 12-bit range 0..{MAX_RAW}"
            )
    if not 0 <= sequence < 2**32:
        raise DeviceInputError("sequence", f"got {sequence}; 0 .. 2**32-1")
    if not 0 <= timestamp_us < 2**64:
        raise DeviceInputError("timestamp_us", f"got {timestamp_us}; 0 .. 2**64-1")
    payload = grey.astype("<u2").tobytes() + phases.astype("<u2").tobytes()
    header = FrameHeader(
        sequence=sequence,
        use_case_code=uc.code,
        n_frequencies=uc.n_frequencies,
        width=uc.width,
        height=uc.height,
        exposure_us=uc.exposure_us if exposure_us is None else int(exposure_us),
        timestamp_us=int(timestamp_us),
        frequencies_hz=tuple(round(f) for f in uc.frequencies_hz),
        payload_length=len(payload),
        payload_crc32=zlib.crc32(payload),
        illumination_temperature_c=illumination_temperature_c,
    )
    return _pack_header(header) + payload


def decode_frame(data: bytes | bytearray | memoryview) -> WireFrame:
    """Decode and check one whole frame (header plus payload, nothing after it).

    Raises
    ------
    TruncatedFrameError
        Fewer bytes than the header announces (``reason="truncated"``) or no whole header.
    CorruptFrameError
        A CRC does not match (``"header-crc"``, ``"payload-crc"``).
    FrameError
        Anything else that is not a valid frame: ``"magic"``, ``"version"``, ``"length"``
        (bytes after the payload), ``"values"`` (a word above 4095), ``"header"``.
    """
    header = decode_header(bytes(data[:HEADER_SIZE]))
    seq = header.sequence
    total = HEADER_SIZE + header.payload_length
    if len(data) < total:
        raise TruncatedFrameError(
            "truncated",
            f"frame {seq} truncated: {len(data)} of {total} bytes arrived "
            f"({len(data) - HEADER_SIZE} of {header.payload_length} payload bytes)",
            seq,
        )
    if len(data) > total:
        raise FrameError(
            "length", f"frame {seq}: {len(data) - total} bytes after the {total}-byte frame", seq
        )
    payload = memoryview(data)[HEADER_SIZE:total]
    crc = zlib.crc32(payload)
    if crc != header.payload_crc32:
        raise CorruptFrameError(
            "payload-crc",
            f"frame {seq}: payload CRC32 0x{crc:08X} does not match the header's "
            f"0x{header.payload_crc32:08X}",
            seq,
        )
    words = np.frombuffer(payload, dtype="<u2").astype(np.uint16)
    n_bad = int(np.count_nonzero(words > MAX_RAW))
    if n_bad:
        raise FrameError(
            "values",
            f"frame {seq}: {n_bad} words exceed the 12-bit range 0..{MAX_RAW} "
            f"(largest {int(words.max())})",
            seq,
        )
    h, w = header.height, header.width
    images = words.reshape(header.n_images, h, w)
    return WireFrame(
        header=header,
        grey=images[0],
        phases=images[1:].reshape(header.n_frequencies, header.n_phases, h, w),
    )


def wire_to_raw_frame(frame: WireFrame, meta: dict[str, Any] | None = None) -> RawFrame:
    """The :class:`RawFrame` of a decoded frame (C = raw - 2048, float32 DN).

    ``meta`` is merged over ``{"use_case", "sequence", "wire_version"}``.
    """
    h = frame.header
    phases = frame.phases
    saturated = np.any((phases == 0) | (phases == MAX_RAW), axis=(0, 1)) | (frame.grey == MAX_RAW)
    info: dict[str, Any] = {
        "use_case": get_use_case(h.use_case_code).name,
        "sequence": h.sequence,
        "wire_version": h.version,
    }
    info.update(meta or {})
    return RawFrame(
        phase_images=(phases.astype(np.float32) - np.float32(RAW_OFFSET)),
        intensity=frame.grey.astype(np.float32),
        frequencies_hz=np.asarray(h.frequencies_hz, dtype=np.float64),
        saturated=saturated,
        sbi_limit=np.zeros(frame.grey.shape, dtype=bool),
        exposure_s=h.exposure_us * 1e-6,
        timestamp_s=h.timestamp_us * 1e-6,
        meta=info,
        illumination_temperature_c=h.illumination_temperature_c,
    )


def raw_to_wire_values(raw: RawFrame) -> tuple[np.ndarray, np.ndarray]:
    """Quantise a RawFrame to the wire's 12-bit words: ``(grey, phases)`` as uint16.

    ``phases = clip(rint(C + 2048), 0, 4095)``, ``grey = clip(rint(intensity), 0, 4095)``
    (round half to even). NaN or infinite values are refused.
    """
    for name, arr in (("phase_images", raw.phase_images), ("intensity", raw.intensity)):
        if not np.all(np.isfinite(arr)):
            raise DeviceInputError(
                f"frame.{name}", f"{int(np.count_nonzero(~np.isfinite(arr)))} non-finite values"
            )
    phases = np.clip(np.rint(np.asarray(raw.phase_images, np.float64) + RAW_OFFSET), 0, MAX_RAW)
    grey = np.clip(np.rint(np.asarray(raw.intensity, np.float64)), 0, MAX_RAW)
    return grey.astype(np.uint16), phases.astype(np.uint16)


def _check_frequencies(raw: RawFrame, uc: UseCase) -> None:
    freqs = np.asarray(raw.frequencies_hz, dtype=np.float64)
    if freqs.shape != (uc.n_frequencies,) or not np.allclose(freqs, uc.frequencies_hz, atol=1.0):
        raise DeviceInputError(
            "frame.frequencies_hz",
            f"{freqs.tolist()} Hz do not match use case {uc.name} ({list(uc.frequencies_hz)} Hz)",
        )


def encode_raw_frame(
    raw: RawFrame, *, use_case: str | int | UseCase, sequence: int, timestamp_us: int
) -> bytes:
    """Quantise a RawFrame (:func:`raw_to_wire_values`) and encode it as one frame."""
    uc = get_use_case(use_case)
    _check_frequencies(raw, uc)
    grey, phases = raw_to_wire_values(raw)
    exposure_us = round(raw.exposure_s * 1e6) if math.isfinite(raw.exposure_s) else None
    return encode_frame(
        grey,
        phases,
        use_case=uc,
        sequence=sequence,
        timestamp_us=timestamp_us,
        exposure_us=exposure_us,
        illumination_temperature_c=raw.illumination_temperature_c,
    )


def quantize_frame(raw: RawFrame, use_case: str | int | UseCase) -> RawFrame:
    """The frame the wire delivers for ``raw``: what decoding ``encode_raw_frame(raw)`` gives.

    Arrays (phase images, intensity, saturated, sbi_limit, frequencies) and the exposure equal
    those of the decoded frame exactly; the timestamp and ``meta`` are the source's.
    """
    uc = get_use_case(use_case)
    _check_frequencies(raw, uc)
    grey, phases = raw_to_wire_values(raw)
    header = FrameHeader(
        sequence=0,
        use_case_code=uc.code,
        n_frequencies=uc.n_frequencies,
        width=uc.width,
        height=uc.height,
        exposure_us=round(raw.exposure_s * 1e6),
        timestamp_us=0,
        frequencies_hz=tuple(round(f) for f in uc.frequencies_hz),
        payload_length=0,
        payload_crc32=0,
    )
    out = wire_to_raw_frame(WireFrame(header, grey, phases))
    return dataclasses.replace(out, timestamp_s=raw.timestamp_s, meta=dict(raw.meta),
                               illumination_temperature_c=_as_float32(
                                   raw.illumination_temperature_c))


def _as_float32(value: float | None) -> float | None:
    """A temperature as the header's float32 carries it."""
    return None if value is None else float(np.float32(value))


# -- status --------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeviceStatus:
    """The GET_STATUS reply.

    Attributes
    ----------
    wire_version : int
    use_case_code : int
        0 when no use case is configured.
    streaming : bool
    last_error : int
        Why the device stalled the last refused request (:data:`STATUS_ERRORS`), 0 if none.
    width, height : int
    next_sequence : int
        Sequence number the next frame will carry.
    firmware_bcd : int
        Firmware version as BCD (0x0100 = 1.00).
    """

    wire_version: int
    use_case_code: int
    streaming: bool
    last_error: int
    width: int
    height: int
    next_sequence: int
    firmware_bcd: int

    @property
    def last_error_text(self) -> str:
        return STATUS_ERRORS.get(self.last_error, f"undocumented error {self.last_error}")

    @property
    def firmware(self) -> str:
        """``'1.00'`` for 0x0100."""
        return f"{self.firmware_bcd >> 8:x}.{self.firmware_bcd & 0xFF:02x}"


def encode_status(status: DeviceStatus) -> bytes:
    """The 16 bytes of a GET_STATUS reply."""
    return STATUS.pack(
        status.wire_version,
        status.use_case_code,
        int(status.streaming),
        status.last_error,
        status.width,
        status.height,
        status.next_sequence,
        status.firmware_bcd,
    )


def decode_status(data: bytes | bytearray) -> DeviceStatus:
    """Parse a GET_STATUS reply (exactly 16 bytes)."""
    if len(data) != STATUS_SIZE:
        raise ProtocolError(
            f"GET_STATUS reply has {len(data)} bytes, expected {STATUS_SIZE}: {bytes(data)!r}"
        )
    version, code, streaming, last_error, width, height, seq, fw = STATUS.unpack(bytes(data))
    if streaming not in (0, 1):
        raise ProtocolError(f"GET_STATUS streaming byte is {streaming}, expected 0 or 1")
    return DeviceStatus(version, code, bool(streaming), last_error, width, height, seq, fw)
