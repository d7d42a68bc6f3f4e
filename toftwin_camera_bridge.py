"""toftwin's camera bridge: a pico flexx opened with PMD's ``roypy``, streamed over TCP.

One file on purpose: copy it to the PC beside the camera (USB 3 cable length) and run it with
the Python that PMD's royale SDK was built for (royale 4.10: 3.5 on Ubuntu 16.04, 3.7 on
Windows, 3.8 on macOS; this file needs Python 3.8+, numpy and the standard library, nothing of
toftwin)::

    PYTHONPATH=<royale>/python python3 toftwin_camera_bridge.py --port 5600

and point the service at it: ``toftwin serve --camera tcp://LABPC:5600``. A crash inside the SDK
then takes down this process only; the service names the camera and pauses the campaign, and
carries on when the bridge is back. toftwin installs the same module (``toftwin-camera-bridge``
on the PATH), and its own camera client (:mod:`drivers.camera.bridge_client`) and in-process
camera (:mod:`drivers.camera.royale`) use the protocol, the raw-data copy and the royale source
defined here: one home for each.

Protocol (version :data:`PROTOCOL_VERSION`)
-------------------------------------------
Every message is a 12-byte header (``b"TOFB"``, the JSON length and the payload length, both
unsigned 32-bit big-endian), a UTF-8 JSON object, then the payload bytes. The client sends
requests ``{"op": OP, "id": N, ...}``; the bridge answers each with ``{"op": "reply", "id": N,
"ok": true, "result": ...}`` or ``{"op": "reply", "id": N, "ok": false, "error": {"kind": K,
"message": M}}`` (kinds: :data:`ERROR_KINDS`). Requests: ``hello`` (``{"protocol": 1}`` ->
the bridge's versions), ``list_cameras``, ``open`` (``camera``: an id or null for the first,
``use_case``, ``exposure_us``, ``mode``: ``"raw"`` or ``"depth"``, optional), ``use_case``
(``name``), ``exposure`` (``us``),
``start``, ``stop``, ``close``, ``ping``, and for a simulated camera only ``attach_world``
(``url``: the service's simulated world, toftwin's ``drivers.sim.world_link``). The bridge
pushes ``{"op": "frame", "seq": N, ...}`` with one royale ``RawData`` (the fields of
:class:`RawDataCopy`; the payload is the raw frames, ``(n, height, width)`` little-endian
uint16, C order) or, in ``"depth"`` mode, ``{"op": "frame", "kind": "depth", ...}`` with one
royale ``DepthData`` (the fields of :class:`DepthDataCopy`; the payload is its points,
``(height, width, 6)`` little-endian float32), and ``{"op": "event", "kind":
"disconnected" | "error", "camera": ID, "message": M}``.

One client at a time: a new connection replaces the old one (a restarted service finds its
camera again even when the old connection was not closed); when the client goes, the stream
stops and the camera stays open for the next.

royale's raw data (sources in toftwin's ``docs/devices.md``, "Camera (USB)")
-------------------------------------------------------------------------
royale >= 5 delivers ``royale::RawData`` to an ``IRawDataListener``
(``registerRawDataListener``, access level 1); earlier versions to an ``IExtendedDataListener``
(``registerDataListenerExtended``, access level 2: an access code given to ``CameraManager``)
as ``data.getRawData()`` when ``data.hasRawData()``. Failing calls raise ``RuntimeError`` naming
the status (or return it, in some versions).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import queue
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__version__ = "1.0.0"
PROTOCOL_VERSION = 1
MAGIC = b"TOFB"
_HEADER = struct.Struct(">4sII")
#: largest JSON part and payload a peer accepts (a 9-frame pico flexx frame is 0.7 MB)
MAX_JSON_BYTES = 1 << 20
MAX_PAYLOAD_BYTES = 64 << 20
#: what a failed request's ``error.kind`` can say
ERROR_KINDS = ("not_installed", "not_found", "access", "input", "disconnected", "protocol",
               "error")
DEFAULT_PORT = 5600

_log = logging.getLogger("toftwin_camera_bridge")


class BridgeError(RuntimeError):
    """A camera source or the bridge failed; ``kind`` is one of :data:`ERROR_KINDS`."""

    def __init__(self, message: str, kind: str = "error") -> None:
        super().__init__(message)
        self.kind = kind if kind in ERROR_KINDS else "error"


class RawDataLayoutError(BridgeError):
    """royale's raw buffer does not have the layout its fields describe."""

    def __init__(self, message: str) -> None:
        super().__init__(message, "protocol")


# -- royale's raw data as plain Python -------------------------------------------------------
@dataclass(frozen=True)
class RawDataCopy:
    """A copy of one ``royale::RawData`` (royale reuses its buffers after the callback).

    Attributes
    ----------
    width, height : int
    raw_frames : (n, height, width) uint16
        The raw frames in royale's order (``getRawPhase(i)``).
    modulation_frequencies_hz, exposure_times_us : tuple of int
        Per raw frame or per exposure group, as royale gives them.
    raw_frame_count : tuple of int
        Raw frames per exposure group (empty if the royale version has none).
    exposure_group_names : tuple of str
    phase_angles_deg : tuple of int
        Per raw frame (empty if unknown).
    illumination_enabled : tuple of int
        Per raw frame, 1 = illumination on (empty if unknown).
    timestamp_us : int or None
        ``timeStamp`` in microseconds since the epoch, None if it could not be read.
    illumination_temperature_c : float or None
    stream_id : int
    """

    width: int
    height: int
    raw_frames: np.ndarray = field(repr=False)
    modulation_frequencies_hz: tuple[int, ...]
    exposure_times_us: tuple[int, ...]
    raw_frame_count: tuple[int, ...] = ()
    exposure_group_names: tuple[str, ...] = ()
    phase_angles_deg: tuple[int, ...] = ()
    illumination_enabled: tuple[int, ...] = ()
    timestamp_us: int | None = None
    illumination_temperature_c: float | None = None
    stream_id: int = 0


def split_raw_buffer(flat: Any, n: int, width: int, height: int) -> np.ndarray:
    """Raw frames out of royale's flat ``rawData`` buffer: ``(n, height, width)`` uint16.

    Each raw frame occupies ``width * (height + 1)`` words, the first row being pseudo data
    (royale ``RawData::getRawData(idx)``).

    >>> flat = np.arange(2 * 3 * 3, dtype=np.uint16)  # 2 frames of 3 x 2 plus a pseudo row
    >>> split_raw_buffer(flat, 2, 3, 2)[1].tolist()
    [[12, 13, 14], [15, 16, 17]]
    """
    words = np.asarray(flat, dtype=np.uint16).ravel()
    expected = n * width * (height + 1)
    if words.size != expected:
        raise RawDataLayoutError(
            f"raw buffer has {words.size} words; {n} raw frames of {width} x {height} plus one "
            f"pseudo-data row each need {expected}"
        )
    return words.reshape(n, height + 1, width)[:, 1:, :].copy()


def _ints(values: Any) -> tuple[int, ...]:
    if values is None:
        return ()
    return tuple(int(v) for v in values)


def _timestamp_us(value: Any) -> int | None:
    """``RawData.timeStamp`` as an int: a number, or a chrono duration with ``count()``."""
    for convert in (lambda v: int(v), lambda v: int(v.count())):
        try:
            return convert(value)
        except (TypeError, ValueError, AttributeError):
            continue
    return None


def copy_roypy_raw_data(raw: Any) -> RawDataCopy:
    """Copy a roypy ``RawData`` into a :class:`RawDataCopy` (call it inside the callback).

    Uses ``getRawPhase(i)`` for each of the ``sum(rawFrameCount)`` frames when available, else
    the flat ``rawData`` buffer with its pseudo-data rows (:func:`split_raw_buffer`), which must
    hold exactly that many frames.
    """
    width, height = int(raw.width), int(raw.height)
    counts = _ints(getattr(raw, "rawFrameCount", None))
    angles = _ints(getattr(raw, "phaseAngles", None))
    n = sum(counts) if counts else len(angles)
    if hasattr(raw, "getRawPhase") and n:
        frames = np.stack([np.asarray(raw.getRawPhase(i), dtype=np.uint16).reshape(height, width)
                           for i in range(n)])
    else:
        flat = np.asarray(raw.rawData, dtype=np.uint16).ravel()
        # as many frames as royale counts (a buffer of another size is refused, naming it);
        # only a RawData that counts nothing is split by the buffer's own size
        frames = split_raw_buffer(flat, n or flat.size // (width * (height + 1)), width, height)
    temperature = getattr(raw, "illuminationTemperature", None)
    return RawDataCopy(
        width=width,
        height=height,
        raw_frames=frames,
        modulation_frequencies_hz=_ints(getattr(raw, "modulationFrequencies", None)),
        exposure_times_us=_ints(getattr(raw, "exposureTimes", None)),
        raw_frame_count=counts,
        exposure_group_names=tuple(str(s) for s in (getattr(raw, "exposureGroupNames", None)
                                                     or ())),
        phase_angles_deg=angles,
        illumination_enabled=_ints(getattr(raw, "illuminationEnabled", None)),
        timestamp_us=_timestamp_us(getattr(raw, "timeStamp", None)),
        illumination_temperature_c=None if temperature is None else float(temperature),
        stream_id=int(getattr(raw, "streamId", 0) or 0),
    )


#: the channels of a :class:`DepthDataCopy`'s points, in order
DEPTH_CHANNELS = ("x_m", "y_m", "z_m", "noise_m", "grey", "confidence")
#: what a data source can stream: royale's raw data, or its processed depth
MODES = ("raw", "depth")


@dataclass(frozen=True)
class DepthDataCopy:
    """A copy of one ``royale::DepthData`` (royale's processed depth, ``IDepthDataListener``).

    Attributes
    ----------
    width, height : int
    points : (height, width, 6) float32
        Per pixel :data:`DEPTH_CHANNELS`: x, y, z [m] in the camera's frame, royale's noise
        estimate [m] (NaN where royale gives none: royale 5), the grey value [DN], and the
        depth confidence scaled to 0..1 (royale < 5 gives 0..255, royale 5 0..1).
    exposure_times_us : tuple of int
    timestamp_us : int or None
    illumination_temperature_c : float or None
        royale 5 only.
    stream_id : int
    """

    width: int
    height: int
    points: np.ndarray = field(repr=False)
    exposure_times_us: tuple[int, ...] = ()
    timestamp_us: int | None = None
    illumination_temperature_c: float | None = None
    stream_id: int = 0


def copy_roypy_depth_data(data: Any, confidence_full_scale: float = 255.0) -> DepthDataCopy:
    """Copy a roypy ``DepthData`` into a :class:`DepthDataCopy` (call it inside the callback).

    ``npoints()`` where roypy has it (royale 4: x, y, z, noise, grey, confidence; royale 5: x, y,
    z, grey, confidence), else the per-point getters of royale 3 (``getX(i)``, ``getY``,
    ``getZ``, ``getNoise`` where present, ``getGrayValue``, ``getDepthConfidence``).
    ``confidence_full_scale`` is royale's full confidence (255 before royale 5, 1.0 from 5 on).
    """
    width, height = int(data.width), int(data.height)
    points = None
    if hasattr(data, "npoints"):
        with contextlib.suppress(AttributeError):  # royale 3's DepthData has none
            points = np.asarray(data.npoints(), dtype=np.float32)
    if points is None:
        n = width * height
        noise = getattr(data, "getNoise", None)
        columns = [[float(data.getX(i)) for i in range(n)], [float(data.getY(i)) for i in range(n)],
                   [float(data.getZ(i)) for i in range(n)],
                   [float(noise(i)) for i in range(n)] if noise else [float("nan")] * n,
                   [float(data.getGrayValue(i)) for i in range(n)],
                   [float(data.getDepthConfidence(i)) for i in range(n)]]
        points = np.asarray(columns, dtype=np.float32).T.reshape(height, width, 6)
    elif points.shape == (height, width, 5):  # royale 5: no noise channel
        nan = np.full((height, width, 1), np.nan, dtype=np.float32)
        points = np.concatenate([points[..., :3], nan, points[..., 3:]], axis=-1)
    if points.shape != (height, width, 6):
        raise RawDataLayoutError(f"depth points of shape {points.shape}; expected "
                                 f"({height}, {width}, 5 or 6)")
    points = points.copy()
    points[..., 5] /= np.float32(confidence_full_scale)
    temperature = getattr(data, "illuminationTemperature", None)
    return DepthDataCopy(
        width=width, height=height, points=points,
        exposure_times_us=_ints(getattr(data, "exposureTimes", None)),
        timestamp_us=_timestamp_us(getattr(data, "timeStamp", None)),
        illumination_temperature_c=None if temperature is None else float(temperature),
        stream_id=int(getattr(data, "streamId", 0) or 0),
    )


# -- the wire format --------------------------------------------------------------------------
def encode_message(message: dict[str, Any], payload: bytes = b"") -> bytes:
    """One message on the wire (module docstring, "Protocol")."""
    text = json.dumps(message, separators=(",", ":")).encode("utf-8")
    if len(text) > MAX_JSON_BYTES or len(payload) > MAX_PAYLOAD_BYTES:
        raise BridgeError(f"message too large: {len(text)} B of JSON, {len(payload)} B payload",
                          "protocol")
    return _HEADER.pack(MAGIC, len(text), len(payload)) + text + payload


def _read_exactly(sock: socket.socket, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        chunk = sock.recv(min(n - got, 1 << 20))
        if not chunk:
            raise ConnectionError(f"peer closed the connection ({got} of {n} bytes read)")
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def read_message(sock: socket.socket) -> tuple[dict[str, Any], bytes]:
    """The next message from ``sock``: its JSON object and payload.

    Raises ``ConnectionError`` when the peer closes and :class:`BridgeError` (kind
    ``protocol``) for bytes that are not a message of this protocol.
    """
    magic, json_len, payload_len = _HEADER.unpack(_read_exactly(sock, _HEADER.size))
    if magic != MAGIC:
        raise BridgeError(f"not a toftwin camera bridge message (starts {magic!r})", "protocol")
    if json_len > MAX_JSON_BYTES or payload_len > MAX_PAYLOAD_BYTES:
        raise BridgeError(f"message too large: {json_len} B of JSON, {payload_len} B payload",
                          "protocol")
    try:
        message = json.loads(_read_exactly(sock, json_len).decode("utf-8"))
    except ValueError as exc:
        raise BridgeError(f"message is not UTF-8 JSON: {exc}", "protocol") from exc
    if not isinstance(message, dict) or not isinstance(message.get("op"), str):
        raise BridgeError("message is not a JSON object with a string 'op'", "protocol")
    return message, _read_exactly(sock, payload_len)


#: the :class:`RawDataCopy` fields a frame message carries as JSON (the frames are the payload)
_FRAME_FIELDS = ("width", "height", "modulation_frequencies_hz", "exposure_times_us",
                 "raw_frame_count", "exposure_group_names", "phase_angles_deg",
                 "illumination_enabled", "timestamp_us", "illumination_temperature_c",
                 "stream_id")


def frame_message(data: RawDataCopy, seq: int, camera: str) -> tuple[dict[str, Any], bytes]:
    """A frame message for ``data`` (the ``seq``-th frame the bridge sent) and its payload."""
    frames = np.ascontiguousarray(data.raw_frames, dtype="<u2")
    message: dict[str, Any] = {"op": "frame", "seq": seq, "camera": camera,
                               "n_raw": int(frames.shape[0])}
    for name in _FRAME_FIELDS:
        value = getattr(data, name)
        message[name] = list(value) if isinstance(value, tuple) else value
    return message, frames.tobytes()


#: the :class:`DepthDataCopy` fields a depth frame message carries as JSON
_DEPTH_FIELDS = ("width", "height", "exposure_times_us", "timestamp_us",
                 "illumination_temperature_c", "stream_id")


def depth_frame_message(data: DepthDataCopy, seq: int,
                        camera: str) -> tuple[dict[str, Any], bytes]:
    """A frame message (``"kind": "depth"``) for ``data`` and its payload: the points,
    ``(height, width, 6)`` little-endian float32."""
    message: dict[str, Any] = {"op": "frame", "kind": "depth", "seq": seq, "camera": camera}
    for name in _DEPTH_FIELDS:
        value = getattr(data, name)
        message[name] = list(value) if isinstance(value, tuple) else value
    return message, np.ascontiguousarray(data.points, dtype="<f4").tobytes()


def data_from_message(message: dict[str, Any], payload: bytes) -> RawDataCopy | DepthDataCopy:
    """The copy a frame message carries: raw data, or processed depth (``"kind": "depth"``)."""
    if message.get("kind", "raw") != "depth":
        return raw_data_from_message(message, payload)
    try:
        width, height = int(message["width"]), int(message["height"])
        if len(payload) != 4 * 6 * width * height:
            raise BridgeError(f"depth payload has {len(payload)} bytes; {width} x {height} "
                              f"points of 6 float32 need {4 * 6 * width * height}", "protocol")
        stamp = message.get("timestamp_us")
        temperature = message.get("illumination_temperature_c")
        return DepthDataCopy(
            width=width, height=height,
            points=np.frombuffer(payload, dtype="<f4").reshape(height, width, 6).astype(
                np.float32),
            exposure_times_us=_ints(message.get("exposure_times_us")),
            timestamp_us=None if stamp is None else int(stamp),
            illumination_temperature_c=None if temperature is None else float(temperature),
            stream_id=int(message.get("stream_id") or 0))
    except (KeyError, TypeError, ValueError) as exc:
        raise BridgeError(f"depth frame message lacks or garbles a field: {exc!r}",
                          "protocol") from exc


def raw_data_from_message(message: dict[str, Any], payload: bytes) -> RawDataCopy:
    """The :class:`RawDataCopy` a frame message carries (the inverse of :func:`frame_message`)."""
    try:
        n, width, height = int(message["n_raw"]), int(message["width"]), int(message["height"])
        if len(payload) != 2 * n * width * height:
            raise BridgeError(f"frame payload has {len(payload)} bytes; {n} raw frames of "
                              f"{width} x {height} uint16 need {2 * n * width * height}",
                              "protocol")
        frames = np.frombuffer(payload, dtype="<u2").reshape(n, height, width).astype(np.uint16)
        temperature = message.get("illumination_temperature_c")
        stamp = message.get("timestamp_us")
        return RawDataCopy(
            width=width, height=height, raw_frames=frames,
            modulation_frequencies_hz=_ints(message["modulation_frequencies_hz"]),
            exposure_times_us=_ints(message.get("exposure_times_us")),
            raw_frame_count=_ints(message.get("raw_frame_count")),
            exposure_group_names=tuple(str(s) for s in message.get("exposure_group_names")
                                       or ()),
            phase_angles_deg=_ints(message.get("phase_angles_deg")),
            illumination_enabled=_ints(message.get("illumination_enabled")),
            timestamp_us=None if stamp is None else int(stamp),
            illumination_temperature_c=None if temperature is None else float(temperature),
            stream_id=int(message.get("stream_id") or 0),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise BridgeError(f"frame message lacks or garbles a field: {exc!r}", "protocol") from exc


def put_dropping_oldest(bounded: queue.Queue, item: Any) -> int:
    """Put ``item`` into the ``bounded`` queue without blocking: when it is full, the oldest
    items go first (a camera's newest frame is worth more than its oldest). Items dropped."""
    dropped = 0
    while True:
        try:
            bounded.put_nowait(item)
            return dropped
        except queue.Full:
            with contextlib.suppress(queue.Empty):
                bounded.get_nowait()
                dropped += 1


# -- a camera through roypy -------------------------------------------------------------------
INSTALL_HINT = (
    "install PMD's royale SDK (from pmdtec.com; roypy is not on PyPI) and put its python "
    "directory, e.g. <royale>/python, on PYTHONPATH so that 'import roypy' works"
)
#: the environment variable holding royale's access code (level 2: raw data before royale 5)
ACCESS_CODE_VARIABLE = "TOFTWIN_ROYALE_ACCESS_CODE"


def import_roypy() -> Any:
    """The ``roypy`` module, or :class:`BridgeError` (kind ``not_installed``) saying how."""
    try:
        import roypy  # type: ignore[import-not-found]
    except ImportError as exc:
        raise BridgeError(f"royale not installed: cannot import roypy ({exc}); {INSTALL_HINT}",
                          "not_installed") from exc
    return roypy


def _strings(values: Any) -> list[str]:
    if values is None:
        return []
    if hasattr(values, "size") and not isinstance(values, (list, tuple)):
        return [str(values[i]) for i in range(values.size())]
    return [str(v) for v in values]


class RoyaleSource:
    """One camera through ``roypy``: open, use case, exposure, start and stop; every raw frame
    handed to ``on_frame`` as a :class:`RawDataCopy` on royale's thread.

    Failing calls raise :class:`BridgeError` with a ``kind`` (roypy raises ``RuntimeError``
    naming the status, or returns a non-zero status; pupil-labs/pupil-picoflexx
    ``royale/utils.py`` handles both). Nothing is ever raised into royale's thread: a failing
    copy is counted in ``callback_errors``.

    Parameters
    ----------
    roypy : module
        PMD's wrapper (:func:`import_roypy`), or a conformance double.
    on_frame : callable
        Called with each frame's copy (on royale's thread; keep it short).
    access_code : str or None
        royale access code (level 2, raw data before royale 5); ``TOFTWIN_ROYALE_ACCESS_CODE``
        when None.
    mode : "raw" or "depth"
        royale's raw data (``IRawDataListener``, the extended listener before royale 5), or its
        processed depth (``IDepthDataListener``, level 0: no access code), each frame then a
        :class:`DepthDataCopy`; :meth:`open` may switch it.
    """

    backend = "roypy"

    def __init__(self, roypy: Any, on_frame: Callable[[Any], None],
                 access_code: str | None = None, mode: str = "raw") -> None:
        self.roypy = roypy
        self.on_frame = on_frame
        self.access_code = access_code
        self.mode = _checked_mode(mode)
        self.callback_errors: list[str] = []
        self.camera_id: str | None = None
        self._manager: Any = None
        self._cam: Any = None
        self._listener: Any = None
        self.streaming = False

    def describe(self) -> dict[str, Any]:
        version = None
        with contextlib.suppress(Exception):
            version = str(self.roypy.getVersionString())
        return {"backend": self.backend, "royale": version}

    def _call(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        try:
            result = fn(*args)
        except RuntimeError as exc:
            kind = "disconnected" if "DISCONNECTED" in str(exc).upper() else "error"
            raise BridgeError(f"royale {what} failed: {exc}", kind) from exc
        if isinstance(result, int) and not isinstance(result, bool) and result != 0:
            text = ""
            with contextlib.suppress(Exception):  # best effort: the name of the status
                text = f" ({self.roypy.getStatusString(result)})"
            raise BridgeError(f"royale {what} failed with status {result}{text}")
        return result

    def _manager_for(self) -> Any:
        if self._manager is None:
            code = self.access_code or os.environ.get(ACCESS_CODE_VARIABLE)
            self._manager = self.roypy.CameraManager(code) if code else self.roypy.CameraManager()
        return self._manager

    def list_cameras(self) -> list[str]:
        """The ids of the cameras royale sees."""
        return _strings(self._call("getConnectedCameraList",
                                   self._manager_for().getConnectedCameraList))

    def open(self, camera_id: str | None = None, mode: str | None = None) -> dict[str, Any]:
        """Open ``camera_id`` (the first camera when None), register the listener of ``mode``
        (None: the current one); the camera's identity (``id``, ``name``, ``use_cases``,
        ``info``, ``mode``). The camera already open is kept when it is still connected and the
        mode is the same, else opened again (a camera pulled and plugged in again under a
        running bridge)."""
        mode = self.mode if mode is None else _checked_mode(mode)
        if self._cam is not None:
            if camera_id in (None, self.camera_id) and mode == self.mode and self.is_connected():
                return self.identity()
            # another camera, or this one pulled (and perhaps plugged in again): royale's old
            # device is dead for good, so it goes and the camera is created anew
            self.close()
        self.mode = mode
        ids = self.list_cameras()
        if not ids:
            raise BridgeError("royale sees no camera; is the pico flexx plugged in and "
                              "accessible? (a udev rule for its USB ids, docs/devices.md)",
                              "not_found")
        if camera_id is not None and camera_id not in ids:
            raise BridgeError(f"royale camera {camera_id!r} not among {ids}", "not_found")
        chosen = camera_id or ids[0]
        manager = self._manager_for()
        cam = self._call(f"createCamera({chosen!r})", manager.createCamera, chosen)
        if cam is None:
            raise BridgeError(f"royale could not create camera {chosen!r}")
        try:  # a failure leaves nothing half open (a second open() tries again)
            self._call("initialize", cam.initialize)
            self._cam, self.camera_id = cam, chosen
            self._listener, register = self._make_listener()
            try:
                self._call(register, getattr(cam, register), self._listener)
            except BridgeError as exc:
                if register != "registerDataListenerExtended":
                    raise
                raise BridgeError(
                    f"royale camera {chosen}: {exc}; raw data before royale 5 needs an access "
                    f"code of level 2 (access_code=... or the environment variable "
                    f"{ACCESS_CODE_VARIABLE})", "access") from exc
        except BaseException:
            self._cam = self._manager = self._listener = None
            self.camera_id = None
            raise
        return self.identity()

    def _make_listener(self) -> tuple[Any, str]:
        rp, deliver, errors = self.roypy, self._deliver, self.callback_errors
        if self.mode == "depth":

            class DepthListener(rp.IDepthDataListener):  # type: ignore[misc, name-defined]
                def onNewData(self, data: Any) -> None:  # noqa: N802 - royale's name
                    deliver(data)

            return DepthListener(), "registerDataListener"
        if hasattr(rp, "IRawDataListener"):  # royale >= 5

            class RawListener(rp.IRawDataListener):  # type: ignore[misc, name-defined]
                def onNewData(self, data: Any) -> None:  # noqa: N802 - royale's name
                    deliver(data)

            return RawListener(), "registerRawDataListener"

        class ExtendedListener(rp.IExtendedDataListener):  # type: ignore[misc, name-defined]
            def onNewData(self, data: Any) -> None:  # noqa: N802 - royale's name
                try:  # nothing may raise into royale's thread
                    raw = data.getRawData() if data.hasRawData() else None
                except Exception as exc:
                    errors.append(repr(exc))
                    return
                if raw is not None:
                    deliver(raw)

        return ExtendedListener(), "registerDataListenerExtended"

    def _deliver(self, data: Any) -> None:
        """royale's callback thread: copy the data out at once and hand it on."""
        try:
            if self.mode == "depth":  # royale 5 has IRawDataListener and confidences 0..1
                full = 1.0 if hasattr(self.roypy, "IRawDataListener") else 255.0
                self.on_frame(copy_roypy_depth_data(data, full))
            else:
                self.on_frame(copy_roypy_raw_data(data))
        except Exception as exc:  # never raise into royale's thread
            self.callback_errors.append(repr(exc))

    def _require(self) -> Any:
        if self._cam is None:
            raise BridgeError("no camera is open", "not_found")
        return self._cam

    def identity(self) -> dict[str, Any]:
        cam = self._require()
        info: dict[str, str] = {}
        with contextlib.suppress(Exception):  # camera info is optional and varies by module
            pairs = cam.getCameraInfo()
            pairs = pairs if not hasattr(pairs, "size") else [pairs[i]
                                                              for i in range(pairs.size())]
            for pair in pairs:
                key, value = (pair.first, pair.second) if hasattr(pair, "first") else pair
                info[str(key)] = str(value)
        return {"id": _call_str(cam.getId) or self.camera_id,
                "name": _call_str(cam.getCameraName), "use_cases": self.use_cases(),
                "info": info, "mode": self.mode, **self.describe()}

    def use_cases(self) -> list[str]:
        cam = self._require()
        return _strings(self._call("getUseCases", cam.getUseCases))

    def set_use_case(self, name: str) -> None:
        """Select a use case (stops a running stream for the switch and starts it again)."""
        cam = self._require()
        available = self.use_cases()
        if name not in available:
            raise BridgeError(f"{name!r} is not offered by this camera; it offers {available}",
                              "input")
        was = self.streaming
        if was:
            self.stop()
        self._call(f"setUseCase({name})", cam.setUseCase, name)
        if was:
            self.start()

    def set_exposure(self, exposure_us: int) -> None:
        cam = self._require()
        self._call(f"setExposureTime({exposure_us})", cam.setExposureTime, int(exposure_us))

    def start(self) -> None:
        cam = self._require()
        if not self.streaming:
            self._call("startCapture", cam.startCapture)
            self.streaming = True

    def stop(self) -> None:
        if self._cam is not None and self.streaming:
            self.streaming = False
            self._call("stopCapture", self._cam.stopCapture)

    def is_connected(self) -> bool:
        """False when royale says the camera is gone (``isConnected()``); True if unknown."""
        if self._cam is None:
            return False
        try:
            return self._cam.isConnected() is not False
        except AttributeError:  # a royale without isConnected(): unknown
            return True
        except Exception:  # a disconnected camera may raise here too
            return False

    def close(self) -> None:
        """Stop capturing and drop the camera; safe to call twice."""
        cam, self._cam = self._cam, None
        if cam is not None and self.streaming:
            with contextlib.suppress(Exception):
                cam.stopCapture()
        self.streaming = False
        self._manager = self._listener = None


def _checked_mode(mode: str) -> str:
    if mode not in MODES:
        raise BridgeError(f"mode {mode!r}; allowed: {', '.join(MODES)}", "input")
    return mode


def _call_str(fn: Callable[[], Any]) -> str | None:
    """A royale getter returning a string (or ``(status, string)`` in some wrappers)."""
    try:
        value = fn()
    except Exception:  # optional information
        return None
    if isinstance(value, tuple) and len(value) == 2:
        value = value[1]
    return None if value is None else str(value)


# -- the server -------------------------------------------------------------------------------
class BridgeServer:
    """Serve one camera source over TCP (module docstring, "Protocol").

    Parameters
    ----------
    make_source : callable
        ``make_source(on_frame)`` -> a source with the methods of :class:`RoyaleSource`
        (``describe``, ``list_cameras``, ``open``, ``identity``, ``set_use_case``,
        ``set_exposure``, ``start``, ``stop``, ``is_connected``, ``close``).
    host, port : str, int
        Where to listen (port 0: any free port, see :attr:`address`).
    queue_frames : int
        Frames held for a slow client; beyond it the oldest is dropped and counted.
    """

    def __init__(self, make_source: Callable[[Callable[[Any], None]], Any],
                 host: str = "127.0.0.1", port: int = DEFAULT_PORT, queue_frames: int = 8) -> None:
        self.source = make_source(self._on_frame)
        self._listener = socket.create_server((host, port))
        self.address: tuple[str, int] = self._listener.getsockname()[:2]
        self._frames: queue.Queue[RawDataCopy | DepthDataCopy] = queue.Queue(
            maxsize=queue_frames)
        self._client: socket.socket | None = None
        self._send_lock = threading.Lock()
        self._source_lock = threading.Lock()
        self._stop = threading.Event()
        self.seq = 0
        self.dropped = 0
        self._threads: list[threading.Thread] = []

    # life cycle
    def start(self) -> BridgeServer:
        for target, name in ((self._accept_loop, "bridge-accept"),
                             (self._send_loop, "bridge-send")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        _log.info("camera bridge listening on %s:%d (%s)", *self.address,
                  self.source.describe().get("backend"))
        return self

    def close(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):  # wakes the accept() blocked in another thread
            self._listener.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self._listener.close()
        self._drop_client()
        with self._source_lock, contextlib.suppress(Exception):
            self.source.close()

    def __enter__(self) -> BridgeServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def serve_forever(self) -> None:
        self.start()
        try:
            while not self._stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    # frames
    def _on_frame(self, data: RawDataCopy | DepthDataCopy) -> None:
        self.dropped += put_dropping_oldest(self._frames, data)

    def _report_callback_errors(self, reported: int) -> int:
        """Push an ``error`` event for the callback errors after the first ``reported``;
        how many are reported now."""
        errors = getattr(self.source, "callback_errors", None) or ()
        count = len(errors)  # read once: royale's thread may append meanwhile (no copy per frame)
        if count > reported:
            self._push({"op": "event", "kind": "error",
                        "camera": getattr(self.source, "camera_id", None),
                        "message": f"{count - reported} frame(s) lost in royale's callback; "
                                   f"the last: {errors[count - 1]}"})
        return count

    def _send_loop(self) -> None:
        camera_gone_reported = False
        errors_reported = 0
        while not self._stop.is_set():
            errors_reported = self._report_callback_errors(errors_reported)
            try:
                data = self._frames.get(timeout=0.2)
            except queue.Empty:
                streaming = getattr(self.source, "streaming", False)
                if streaming and not camera_gone_reported and not self.source.is_connected():
                    camera_gone_reported = True
                    self._push({"op": "event", "kind": "disconnected",
                                "camera": getattr(self.source, "camera_id", None),
                                "message": "the camera is no longer connected"})
                continue
            camera_gone_reported = False
            self.seq += 1
            encode = depth_frame_message if isinstance(data, DepthDataCopy) else frame_message
            message, payload = encode(data, self.seq,
                                      str(getattr(self.source, "camera_id", "") or ""))
            message["dropped"] = self.dropped
            self._push(message, payload)

    def _push(self, message: dict[str, Any], payload: bytes = b"") -> bool:
        client = self._client
        if client is None:
            return False
        try:
            with self._send_lock:
                client.sendall(encode_message(message, payload))
            return True
        except OSError:
            self._drop_client(client)
            return False

    # clients
    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, peer = self._listener.accept()
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            if self._client is not None:
                _log.info("a new client (%s:%d) replaces the current one", *peer[:2])
            self._drop_client()
            self._client = conn
            threading.Thread(target=self._client_loop, args=(conn,), name="bridge-client",
                             daemon=True).start()

    def _drop_client(self, which: socket.socket | None = None) -> None:
        """Close the current client (only if it is still ``which``); stop the stream."""
        client = self._client
        if client is None or (which is not None and client is not which):
            return
        self._client = None
        with contextlib.suppress(OSError):
            client.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            client.close()
        with self._source_lock, contextlib.suppress(Exception):
            self.source.stop()
        with contextlib.suppress(queue.Empty):
            while True:
                self._frames.get_nowait()

    def _client_loop(self, conn: socket.socket) -> None:
        while not self._stop.is_set() and self._client is conn:
            try:
                message, _ = read_message(conn)
            except (ConnectionError, OSError):
                break
            except BridgeError as exc:
                self._push({"op": "reply", "id": None, "ok": False,
                            "error": {"kind": exc.kind, "message": str(exc)}})
                break
            reply: dict[str, Any] = {"op": "reply", "id": message.get("id")}
            try:
                with self._source_lock:
                    reply.update(ok=True, result=self.handle(message))
            except BridgeError as exc:
                reply.update(ok=False, error={"kind": exc.kind, "message": str(exc)})
            except Exception as exc:  # the SDK raised something unforeseen: say so, go on
                reply.update(ok=False, error={"kind": "error", "message": repr(exc)})
            if not self._push(reply):
                break
        self._drop_client(conn)

    def handle(self, message: dict[str, Any]) -> Any:
        """Carry out one request (the source's lock held); its result."""
        op, src = message["op"], self.source
        if op == "hello":
            if message.get("protocol") != PROTOCOL_VERSION:
                raise BridgeError(f"protocol {message.get('protocol')!r} asked for; this bridge "
                                  f"speaks {PROTOCOL_VERSION}", "protocol")
            return {"protocol": PROTOCOL_VERSION, "bridge": __version__,
                    "python": sys.version.split()[0], **src.describe()}
        if op == "ping":
            return {"time_s": time.time()}
        if op == "list_cameras":
            return src.list_cameras()
        if op == "open":
            identity = (src.open(message.get("camera"), str(message["mode"]))
                        if message.get("mode") is not None else src.open(message.get("camera")))
            if message.get("use_case"):
                src.set_use_case(str(message["use_case"]))
            if message.get("exposure_us") is not None:
                src.set_exposure(int(message["exposure_us"]))
            return identity
        if op == "use_case":
            src.set_use_case(str(message.get("name")))
            return None
        if op == "exposure":
            src.set_exposure(int(message.get("us", 0)))
            return None
        if op == "start":
            src.start()
            return None
        if op == "stop":
            src.stop()
            return None
        if op == "attach_world":  # a simulated camera films the client's simulated world
            attach = getattr(src, "attach_world", None)
            if attach is None:
                raise BridgeError("this bridge's camera is real: it films no simulated world",
                                  "input")
            attach(str(message.get("url")))
            return None
        if op == "close":
            src.close()
            return None
        raise BridgeError(f"unknown op {op!r}", "protocol")


def main(argv: Sequence[str] | None = None) -> int:
    """``toftwin-camera-bridge [--host H] [--port P] [--access-code C]``: serve the camera."""
    parser = argparse.ArgumentParser(prog="toftwin-camera-bridge", description=__doc__.split(
        "\n")[0])
    parser.add_argument("--host", default="0.0.0.0", help="address to listen on")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port")
    parser.add_argument("--access-code", default=None,
                        help=f"royale access code (else ${ACCESS_CODE_VARIABLE})")
    parser.add_argument("--log-level", default="INFO")
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if not 0 <= args.port <= 65535:
        parser.error(f"--port: got {args.port}; 0..65535")
    try:
        roypy = import_roypy()
    except BridgeError as exc:
        print(f"toftwin-camera-bridge: {exc}", file=sys.stderr)
        return 2
    server = BridgeServer(lambda on_frame: RoyaleSource(roypy, on_frame, args.access_code),
                          args.host, args.port)
    server.serve_forever()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
