"""Streaming from a real pico flexx through PMD's royale SDK (Python module ``roypy``).

``roypy`` ships with royale (``<royale>/python``, not on PyPI). This module imports without it:
:func:`royale_available` says whether it is there, and :class:`RoyaleCamera` raises
:class:`RoyaleNotInstalledError` ("royale not installed", with the fix) when it is not.

royale's raw data, as we use it (sources in ``docs/devices.md``, "Camera (USB)")
-------------------------------------------------------------------------------
- A listener receives ``royale::RawData``: royale >= 5 through ``IRawDataListener`` /
  ``ICameraDevice.registerRawDataListener`` (level 1); earlier versions through
  ``IExtendedDataListener`` / ``registerDataListenerExtended`` (access level 2, an access code
  given to ``CameraManager``), where ``data.hasRawData()`` / ``data.getRawData()`` hold it.
  royale's sample ``sample_raw_data.py`` reads it exactly so.
- ``RawData`` fields: ``timeStamp`` (microseconds since 1970 in royale >= 3.x headers),
  ``streamId``, ``width``, ``height``, ``rawData`` (uint16 words), ``exposureGroupNames``,
  ``rawFrameCount`` (raw frames per exposure group), ``modulationFrequencies`` and
  ``exposureTimes`` ("for each sequence"), ``illuminationTemperature``, ``phaseAngles`` and
  ``illuminationEnabled`` (per raw frame). ``getRawPhase(i)`` returns raw frame ``i``
  (``width * height`` words); in the flat ``rawData`` buffer every raw frame is preceded by one
  row of pseudo data (``getRawData(idx)`` = ``&rawData[idx * width * (height + 1) + width]``).
- A pico flexx use case is a grey raw frame set (one frame, exposure group ``"gray"``) and one
  four-phase set (0, 90, 180, 270 degrees) per modulation frequency; royale can put the grey
  frame first or last (``IntensityPhaseOrder``).

The conversion :func:`royale_to_raw_frame` is a pure function of a :class:`RoyaleRawData` (a plain
copy of ``RawData`` made in the callback by :func:`copy_roypy_raw_data`): it finds the grey frame
(the exposure group of one frame, else the one frame with illumination off, else the first),
groups the other frames in fours by frequency, orders each group by phase angle, and applies our
convention C = raw - 2048 (12-bit values in 16-bit words; ``value_shift`` for left-aligned data).
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.camera.protocol import CameraError, CameraIdentity, CameraNotFoundError
from drivers.camera.wire import MAX_RAW, N_PHASES, RAW_OFFSET, UseCase, get_use_case
from drivers.errors import DeviceInputError, DeviceTimeoutError, ProtocolError
from sim_core.raw import RawFrame

try:  # royale's Python wrapper; absent on most machines (not on PyPI)
    import roypy  # type: ignore[import-not-found]

    _IMPORT_ERROR: str | None = None
except ImportError as exc:  # pragma: no cover - depends on the machine
    roypy = None
    _IMPORT_ERROR = str(exc)

__all__ = [
    "INSTALL_HINT",
    "RoyaleCamera",
    "RoyaleDataError",
    "RoyaleNotInstalledError",
    "RoyaleRawData",
    "copy_roypy_raw_data",
    "royale_available",
    "royale_to_raw_frame",
    "split_raw_buffer",
]

_log = logging.getLogger(__name__)

INSTALL_HINT = (
    "install PMD's royale SDK (from pmdtec.com; roypy is not on PyPI) and put its python "
    "directory, e.g. <royale>/python, on PYTHONPATH so that 'import roypy' works"
)


class RoyaleNotInstalledError(CameraError):
    """The royale SDK's Python module ``roypy`` cannot be imported."""


class RoyaleDataError(ProtocolError):
    """Raw data from royale does not have the form a pico flexx use case gives."""


def royale_available() -> bool:
    """True when ``roypy`` imports."""
    return roypy is not None


def require_roypy() -> Any:
    """The ``roypy`` module, or :class:`RoyaleNotInstalledError` saying how to get it."""
    if roypy is None:
        raise RoyaleNotInstalledError(
            f"royale not installed: cannot import roypy ({_IMPORT_ERROR}); {INSTALL_HINT}"
        )
    return roypy


# -- royale's raw data as plain Python -------------------------------------------------------
@dataclass(frozen=True)
class RoyaleRawData:
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


def split_raw_buffer(
    flat: Sequence[int] | np.ndarray, n: int, width: int, height: int
) -> np.ndarray:
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
        raise RoyaleDataError(
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


def copy_roypy_raw_data(raw: Any) -> RoyaleRawData:
    """Copy a roypy ``RawData`` into a :class:`RoyaleRawData` (call it inside the callback).

    Uses ``getRawPhase(i)`` for each of the ``sum(rawFrameCount)`` frames when available, else
    the flat ``rawData`` buffer with its pseudo-data rows (:func:`split_raw_buffer`).
    """
    width, height = int(raw.width), int(raw.height)
    counts = _ints(getattr(raw, "rawFrameCount", None))
    angles = _ints(getattr(raw, "phaseAngles", None))
    n = sum(counts) if counts else len(angles)
    if hasattr(raw, "getRawPhase") and n:
        frames = np.stack(
            [
                np.asarray(raw.getRawPhase(i), dtype=np.uint16).reshape(height, width)
                for i in range(n)
            ]
        )
    else:
        flat = np.asarray(raw.rawData, dtype=np.uint16).ravel()
        per_frame = width * (height + 1)
        frames = split_raw_buffer(flat, flat.size // per_frame, width, height)
    temperature = getattr(raw, "illuminationTemperature", None)
    return RoyaleRawData(
        width=width,
        height=height,
        raw_frames=frames,
        modulation_frequencies_hz=_ints(getattr(raw, "modulationFrequencies", None)),
        exposure_times_us=_ints(getattr(raw, "exposureTimes", None)),
        raw_frame_count=counts,
        exposure_group_names=tuple(
            str(s) for s in (getattr(raw, "exposureGroupNames", None) or ())
        ),
        phase_angles_deg=angles,
        illumination_enabled=_ints(getattr(raw, "illuminationEnabled", None)),
        timestamp_us=_timestamp_us(getattr(raw, "timeStamp", None)),
        illumination_temperature_c=None if temperature is None else float(temperature),
        stream_id=int(getattr(raw, "streamId", 0) or 0),
    )


def _per_frame(values: tuple[int, ...], counts: tuple[int, ...], n: int, what: str) -> list[int]:
    """Values given per raw frame or per exposure group, expanded to one per raw frame."""
    if len(values) == n:
        return list(values)
    if counts and len(values) == len(counts) and sum(counts) == n:
        return [v for v, c in zip(values, counts, strict=True) for _ in range(c)]
    raise RoyaleDataError(
        f"{len(values)} {what} for {n} raw frames in exposure groups {list(counts)}: "
        "neither one per raw frame nor one per exposure group"
    )


def _grey_index(data: RoyaleRawData, n: int) -> tuple[int, str]:
    """Index of the grey raw frame and how it was found."""
    counts = data.raw_frame_count
    if counts and sum(counts) == n:
        singles = [g for g, c in enumerate(counts) if c == 1]
        if len(singles) == 1:
            return sum(counts[: singles[0]]), "exposure group of one raw frame"
    if len(data.illumination_enabled) == n:
        dark = [i for i, on in enumerate(data.illumination_enabled) if not on]
        if len(dark) == 1:
            return dark[0], "illumination disabled"
    return 0, "assumed first (royale reported no groups or illumination flags)"


def royale_to_raw_frame(
    data: RoyaleRawData,
    *,
    use_case: str | UseCase | None = None,
    value_shift: int = 0,
    timestamp_s: float | None = None,
    meta: dict[str, Any] | None = None,
) -> RawFrame:
    """Convert one copy of royale raw data into a :class:`RawFrame` (pure; no roypy needed).

    Parameters
    ----------
    data : RoyaleRawData
        ``1 + 4 n_f`` raw frames of 12-bit values.
    use_case : name, UseCase or None
        When given, the frequencies found must be the use case's (same order).
    value_shift : int
        Right shift applied to every word first (4 for 12-bit values stored left-aligned).
    timestamp_s : float or None
        Used when royale's timestamp could not be read (the host's arrival time).
    meta : dict or None
        Merged into the frame's metadata.

    Raises
    ------
    RoyaleDataError
        Shapes, frame counts, frequencies or phase angles that a pico flexx use case cannot
        produce, or values above 4095 after the shift; the message says which.
    """
    if not 0 <= value_shift <= 4:
        raise DeviceInputError("value_shift", f"got {value_shift!r}; 0..4 bits")
    frames = np.asarray(data.raw_frames)
    n = frames.shape[0] if frames.ndim == 3 else -1
    if frames.ndim != 3 or frames.shape[1:] != (data.height, data.width):
        raise RoyaleDataError(
            f"raw frames of shape {frames.shape}; expected (n, {data.height}, {data.width})"
        )
    if n < 1 + N_PHASES or (n - 1) % N_PHASES:
        raise RoyaleDataError(f"{n} raw frames; a use case gives 1 grey + 4 per frequency")
    words = frames.astype(np.uint16) >> np.uint16(value_shift)
    if int(words.max()) > MAX_RAW:
        raise RoyaleDataError(
            f"raw values up to {int(words.max())} exceed 12 bits (0..{MAX_RAW}); for 12-bit "
            "values stored left-aligned in 16-bit words pass value_shift=4"
        )
    counts = data.raw_frame_count
    freqs = _per_frame(data.modulation_frequencies_hz, counts, n, "modulation frequencies")
    exposures = (
        _per_frame(data.exposure_times_us, counts, n, "exposure times")
        if data.exposure_times_us
        else [0] * n
    )
    grey, grey_source = _grey_index(data, n)
    phase_idx = [i for i in range(n) if i != grey]
    sets: list[list[int]] = []
    for i in phase_idx:
        if sets and len(sets[-1]) < N_PHASES:
            if freqs[i] != freqs[sets[-1][0]]:
                raise RoyaleDataError(
                    f"raw frame {i} at {freqs[i]} Hz inside a four-phase set at "
                    f"{freqs[sets[-1][0]]} Hz (frequencies per frame: {freqs})"
                )
            sets[-1].append(i)
        else:
            sets.append([i])
    if len(data.phase_angles_deg) == n:
        ordered = []
        for s in sets:
            angles = [data.phase_angles_deg[i] % 360 for i in s]
            if sorted(angles) != [0, 90, 180, 270]:
                raise RoyaleDataError(
                    f"phase angles {angles} deg of raw frames {s}; expected 0, 90, 180, 270"
                )
            ordered.append([i for _, i in sorted(zip(angles, s, strict=True))])
        sets = ordered
    set_freqs = tuple(float(freqs[s[0]]) for s in sets)
    uc = None if use_case is None else get_use_case(use_case)
    if uc is not None and (
        len(set_freqs) != uc.n_frequencies
        or any(abs(a - b) > 1.0 for a, b in zip(set_freqs, uc.frequencies_hz, strict=False))
    ):
        raise RoyaleDataError(
            f"frequencies {list(set_freqs)} Hz do not match use case {uc.name} "
            f"({list(uc.frequencies_hz)} Hz)"
        )
    phases = words[np.array(sets)]  # (n_f, 4, H, W)
    grey_img = words[grey]
    saturated = np.any((phases == 0) | (phases == MAX_RAW), axis=(0, 1)) | (grey_img == MAX_RAW)
    if data.timestamp_us is not None:
        stamp, stamp_source = data.timestamp_us * 1e-6, "royale"
    else:
        stamp = time.time() if timestamp_s is None else timestamp_s
        stamp_source = "host"
    info: dict[str, Any] = {
        "backend": "royale",
        "use_case": uc.name if uc else None,
        "grey_index": grey,
        "grey_index_source": grey_source,
        "exposure_times_us": [exposures[s[0]] for s in sets],
        "grey_exposure_us": exposures[grey],
        "exposure_group_names": list(data.exposure_group_names),
        "illumination_temperature_c": data.illumination_temperature_c,
        "timestamp_source": stamp_source,
        "stream_id": data.stream_id,
    }
    info.update(meta or {})
    exposure_us = exposures[sets[0][0]] or (uc.exposure_us if uc else 0)
    return RawFrame(
        phase_images=phases.astype(np.float32) - np.float32(RAW_OFFSET),
        intensity=grey_img.astype(np.float32),
        frequencies_hz=np.asarray(set_freqs, dtype=np.float64),
        saturated=saturated,
        sbi_limit=np.zeros(grey_img.shape, dtype=bool),
        exposure_s=exposure_us * 1e-6,
        timestamp_s=stamp,
        meta=info,
        illumination_temperature_c=data.illumination_temperature_c,
    )


# -- the camera ------------------------------------------------------------------------------
def _check(result: Any, what: str) -> Any:
    """royale calls return a CameraStatus (0 = SUCCESS) in some versions; raise on failure."""
    if isinstance(result, int) and not isinstance(result, bool) and result != 0:
        text = ""
        with contextlib.suppress(Exception):  # best effort: the name of the status
            text = f" ({roypy.getStatusString(result)})"
        raise CameraError(f"royale {what} failed with status {result}{text}")
    return result


def _call(what: str, fn: Callable[..., Any], *args: Any) -> Any:
    """One roypy call; its failures as :class:`CameraError`.

    roypy reports a failing ``CameraStatus`` by raising ``RuntimeError`` (some calls return the
    status instead; pupil-labs/pupil-picoflexx ``royale/utils.py`` handles both), which is not a
    :class:`CameraError`: found by the roypy double (``tests/roypy_double``).
    """
    try:
        result = fn(*args)
    except RuntimeError as exc:
        raise CameraError(f"royale {what} failed: {exc}") from exc
    return _check(result, what)


def _strings(values: Any) -> list[str]:
    if values is None:
        return []
    if hasattr(values, "size") and callable(values.size):
        return [str(values[i]) for i in range(values.size())]
    return [str(v) for v in values]


class RoyaleCamera:
    """A pico flexx streamed through royale, implementing :class:`~drivers.camera.CameraProtocol`.

    Parameters
    ----------
    camera_id : str or None
        royale camera id (``getConnectedCameraList()``); the first camera when None.
    use_case : str
        royale use case name configured at :meth:`connect`.
    access_code : str or None
        royale access code (level 2, needed for raw data before royale 5); the environment
        variable ``TOFTWIN_ROYALE_ACCESS_CODE`` when None.
    frame_timeout_s : float
        Longest wait for one frame in :meth:`capture`.
    queue_size : int
        Frames buffered between royale's callback thread and :meth:`capture`; when full the
        oldest is dropped and counted in ``dropped``.
    value_shift : int
        See :func:`royale_to_raw_frame`.
    """

    def __init__(
        self,
        camera_id: str | None = None,
        *,
        use_case: str | UseCase = "MODE_5_45FPS_500",
        access_code: str | None = None,
        frame_timeout_s: float = 2.0,
        queue_size: int = 8,
        value_shift: int = 0,
    ) -> None:
        self.camera_id = camera_id
        self._use_case = get_use_case(use_case)
        self.access_code = access_code
        self.frame_timeout_s = frame_timeout_s
        self.value_shift = value_shift
        self._queue: queue.Queue[tuple[float, RoyaleRawData]] = queue.Queue(maxsize=queue_size)
        self._lock = threading.Lock()
        self._manager: Any = None
        self._cam: Any = None
        self._listener: Any = None
        self._streaming = False
        self.dropped = 0
        self.callback_errors: list[str] = []
        self._opened_id: str | None = None

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the camera through royale, register the raw-data listener, set the use case."""
        if self._cam is not None:
            return
        rp = require_roypy()
        code = self.access_code or os.environ.get("TOFTWIN_ROYALE_ACCESS_CODE")
        self._manager = rp.CameraManager(code) if code else rp.CameraManager()
        ids = _strings(self._manager.getConnectedCameraList())
        if not ids:
            raise CameraNotFoundError(
                "royale sees no camera; is the pico flexx plugged in and accessible? "
                "(drivers.diagnostics.list_devices() shows permission problems with the fix)"
            )
        if self.camera_id is not None and self.camera_id not in ids:
            raise CameraNotFoundError(f"royale camera {self.camera_id!r} not among {ids}")
        chosen = self.camera_id or ids[0]
        cam = _call(f"createCamera({chosen!r})", self._manager.createCamera, chosen)
        if cam is None:
            raise CameraError(f"royale could not create camera {chosen!r}")
        try:  # a failure leaves nothing half open (a second connect() tries again)
            _call("initialize", cam.initialize)
            self._cam, self._opened_id = cam, chosen
            self._listener, register = self._make_listener(rp)
            try:
                _call(register, getattr(cam, register), self._listener)
            except CameraError as exc:
                if register != "registerDataListenerExtended":
                    raise
                raise CameraError(
                    f"royale camera {chosen}: {exc}; raw data before royale 5 needs an access "
                    "code of level 2 (RoyaleCamera(access_code=...) or the environment variable "
                    "TOFTWIN_ROYALE_ACCESS_CODE)"
                ) from exc
            self.configure(self._use_case)
        except BaseException:
            self._cam = self._manager = self._listener = None
            raise

    def _make_listener(self, rp: Any) -> tuple[Any, str]:
        on_raw = self._on_raw
        if hasattr(rp, "IRawDataListener"):  # royale >= 5

            class RawListener(rp.IRawDataListener):  # type: ignore[misc, name-defined]
                def onNewData(self, data: Any) -> None:  # noqa: N802 - royale's name
                    on_raw(data)

            return RawListener(), "registerRawDataListener"

        errors = self.callback_errors

        class ExtendedListener(rp.IExtendedDataListener):  # type: ignore[misc, name-defined]
            def onNewData(self, data: Any) -> None:  # noqa: N802 - royale's name
                try:  # nothing may raise into royale's thread (found by the roypy double)
                    raw = data.getRawData() if data.hasRawData() else None
                except Exception as exc:
                    errors.append(repr(exc))
                    return
                if raw is not None:
                    on_raw(raw)

        return ExtendedListener(), "registerDataListenerExtended"

    def _on_raw(self, raw: Any) -> None:
        """royale's callback thread: copy the data out at once and queue it."""
        try:
            item = (time.time(), copy_roypy_raw_data(raw))
        except Exception as exc:  # never raise into royale's thread
            self.callback_errors.append(repr(exc))
            return
        while True:
            try:
                self._queue.put_nowait(item)
                return
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    self._queue.get_nowait()
                    self.dropped += 1

    def close(self) -> None:
        """Stop capturing and drop the camera; safe to call twice."""
        cam, self._cam = self._cam, None
        if cam is not None:
            if self._streaming:
                with contextlib.suppress(Exception):
                    cam.stopCapture()
            self._streaming = False
        self._manager = None
        self._listener = None

    def __enter__(self) -> RoyaleCamera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _require(self) -> Any:
        if self._cam is None:
            self.connect()
        return self._cam

    # -- Camera protocol ----------------------------------------------------------------------
    @property
    def use_case(self) -> UseCase:
        return self._use_case

    def configure(self, use_case: str | UseCase) -> None:
        uc = get_use_case(use_case)
        cam = self._require()
        available = _strings(_call("getUseCases", cam.getUseCases))
        if uc.name not in available:
            raise DeviceInputError(
                "use_case", f"{uc.name!r} is not offered by this camera; it offers {available}"
            )
        was_streaming = self._streaming
        if was_streaming:
            self.stop()
        _call(f"setUseCase({uc.name})", cam.setUseCase, uc.name)
        self._use_case = uc
        self._drain()  # frames of the previous use case (found by the roypy double)
        if was_streaming:
            self.start()

    def start(self) -> None:
        cam = self._require()
        if not self._streaming:
            _call("startCapture", cam.startCapture)
            self._streaming = True

    def stop(self) -> None:
        if self._cam is not None and self._streaming:
            self._streaming = False
            _call("stopCapture", self._cam.stopCapture)

    def _drain(self) -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                self._queue.get_nowait()

    def capture(self, n: int = 1) -> list[RawFrame]:
        """The next ``n`` raw frames converted by :func:`royale_to_raw_frame`.

        A one-shot capture (camera not streaming) starts the camera, keeps only frames that
        arrive after the start, and stops it again.
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise DeviceInputError("n", f"got {n!r}; an integer >= 1 frames")
        self._require()
        one_shot = not self._streaming
        if one_shot:
            self._drain()
            self.start()
        frames: list[RawFrame] = []
        try:
            while len(frames) < n:
                try:
                    arrived, data = self._queue.get(timeout=self.frame_timeout_s)
                except queue.Empty:
                    raise self._no_frame_error(len(frames), n) from None
                frames.append(
                    royale_to_raw_frame(
                        data,
                        use_case=self._use_case,
                        value_shift=self.value_shift,
                        timestamp_s=arrived,
                        meta={"device": self.camera_id},
                    )
                )
        finally:
            if one_shot:
                try:
                    self.stop()
                except CameraError as exc:
                    _log.warning("royale camera: stop after capture failed: %s", exc)
        return frames

    def _no_frame_error(self, got: int, n: int) -> CameraError | DeviceTimeoutError:
        """Why no frame came: a disconnected camera (``isConnected()`` false), else a timeout.

        Both name the camera (royale stops delivering when the camera is unplugged; found by
        the roypy double).
        """
        who = f"royale camera {self._opened_id or self.camera_id or '(first)'}"
        detail = f"{got} of {n} frames; callback errors: {self.callback_errors[-3:]}"
        connected: Any = True
        with contextlib.suppress(Exception):  # a disconnected camera may raise here too
            connected = self._cam.isConnected() if self._cam is not None else True
        if connected is False:
            return CameraError(f"{who}: disconnected (isConnected() is false); {detail}")
        return DeviceTimeoutError(
            f"{who}: no raw frame within {self.frame_timeout_s:g} s ({detail})"
        )

    def identity(self) -> CameraIdentity:
        cam = self._require()
        cam_id = _call_str(cam.getId)
        name = _call_str(cam.getCameraName)
        extra: dict[str, str] = {}
        with contextlib.suppress(Exception):  # camera info is optional and varies by module
            info = cam.getCameraInfo()
            pairs = info if not hasattr(info, "size") else [info[i] for i in range(info.size())]
            for pair in pairs:
                key, value = (pair.first, pair.second) if hasattr(pair, "first") else pair
                extra[str(key)] = str(value)
        return CameraIdentity(
            model=name or "royale camera",
            serial=cam_id or (self.camera_id or ""),
            product=name,
            backend="royale",
            extra=extra,
        )


def _call_str(fn: Callable[[], Any]) -> str | None:
    """A royale getter returning a string (or ``(status, string)`` in some wrappers)."""
    try:
        value = fn()
    except Exception:  # optional information
        return None
    if isinstance(value, tuple) and len(value) == 2:
        value = value[1]
    return None if value is None else str(value)
