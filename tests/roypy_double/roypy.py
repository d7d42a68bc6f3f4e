# ruff: noqa: N815, N816
"""A conformance double of PMD's ``roypy`` (royale's Python wrapper) for tests and CI.

Importable as ``roypy`` when this directory is on ``sys.path``; needs only numpy and the
standard library, runs on Python 3.8+. It imitates the Python surface a camera client uses, for
three royale generations, and streams synthetic raw frames of the pico flexx use cases on a
thread of its own. PMD's files are under PMD's proprietary "Royale License for camera systems";
nothing here is copied from them: the double is written from the API facts (names, signatures,
call order, field names, status codes) collected in the research notes of issue 28.

Sources followed (repository + path; the notes give commits)
-------------------------------------------------------------
Camera info (``CameraManager``, ``getConnectedCameraList`` as a vector with ``size()``,
``createCamera``, ``initialize`` first, ``getId``, ``getCameraName``, ``getMaxSensorWidth/Height``,
``getUseCases``, ``getNumberOfStreams``, ``getCurrentUseCase``, ``getCameraInfo`` as key/value
tuples, ``getLensParameters``):

- k5iogura/libroyale-LINUX-arm ``3.21.1.70/python/sample_camera_info.py``,
  ``3.21.1.70/python/roypy_sample_utils.py``, ``3.21.1.70/python/roypy.py`` and ``README.md``
  (pico flexx use-case list, camera-info example, 224 x 171);
- niravatgit/Moveit_Igus_RL_DP5 ``pmd flex2/sample_camera_info.py``, ``pmd flex2/roypy.py``,
  ``pmd flex2/roypy_sample_utils.py`` (royale 5.4: ``LensParamMap``, ``setCallbackData``);
- pmdtechnologies/SampleYOLO ``sample_yolo.py`` (lens-parameter keys, ``npoints()`` channels per
  generation, ``asReplay()`` raising ``SystemError`` on a live camera).

Retrieve data (``IDepthDataListener`` with ``super().__init__()``, ``registerDataListener``,
``setUseCase``, ``startCapture`` / ``stopCapture``, data valid only inside ``onNewData``,
``PythonEventListener.onEventPython`` in 5.x):

- k5iogura/libroyale-LINUX-arm ``3.21.1.70/python/sample_retrieve_data.py``;
  manganarofabio/gestures-collector ``sample_retrieve_data.py``, ``roypy.py``;
- niravatgit/Moveit_Igus_RL_DP5 ``pmd flex2/sample_retrieve_data.py``;
- royale's own roypy unit tests (level 1 / level 2; index ids 2208878410, 1543767195 in the
  notes): ``setExposureTime`` and ``setUseCase`` while capturing, ``getVersion`` /
  ``getVersionString``, ``getExposureLimits``.

Raw data (3.x/4.x: ``IExtendedDataListener`` + ``registerDataListenerExtended``, level 2, data
with ``hasRawData()`` / ``getRawData()``, ``rawFrameCount`` per exposure group, ``getRawPhase(i)``;
5.x: ``IRawDataListener`` + ``registerRawDataListener``, level 1, one flat buffer with a
pseudo-data row before every raw frame, ``getNumberOfRawFrames``, ``getPseudoData``,
``modulationScheme``; ``setCallbackData`` level 2 and only effective at the next start):

- PMD's 3.x Python raw-data sample ``sample_raw_data.py`` (index id 2388082549 in the notes);
- headers: mdkennedy3/precision_pouring_upenn
  ``pico_flexx_driver/royale/libroyale-3.11.0.0-LINUX-arm-64Bit/include/royale/RawData.hpp`` and
  ``.../libroyale-3.7.0.0-LINUX-x86-64Bit/include/royale/IExtendedData.hpp``,
  ``IExtendedDataListener.hpp``, ``Status.hpp``; niravatgit/Moveit_Igus_RL_DP5
  ``sampleROS/royale/include/royale/RawData.hpp``, ``IRawDataListener.hpp``, ``ICameraDevice.hpp``,
  ``CallbackData.hpp``, ``Status.hpp``, ``IEvent.hpp``, ``LensParameters.hpp``.

Recording (``IRecordStopListener.onRecordingStopped(frameCount)``, ``registerRecordListener``,
``startRecording(file, numberOfFrames=0, frameSkip=0, msSkip=0)``, ``stopRecording``):

- k5iogura/libroyale-LINUX-arm ``3.21.1.70/python/sample_record_rrf.py`` (and royale's roypy
  unit tests ``testRecordingTimed`` / ``testRecordingCounted``).

Errors: failing calls raise ``RuntimeError`` whose text names the ``CameraStatus``
(pupil-labs/pupil-picoflexx ``royale/utils.py`` wraps roypy exactly for this and also checks
non-zero returned statuses; ``DOUBLE.status_mode = "return"`` makes the double return the status
instead). A disconnected camera: no more frames, ``isConnected()`` false, calls fail with
``DISCONNECTED``; royale 5 also sends ``ROYALE_DEVICE_DISCONNECTED`` (severity FATAL) to a
``PythonEventListener``; 3.x has no Python event listener (pupil-picoflexx polls
``isConnected()``).

What is *not* documented and so is a choice of this double (each marked "double's choice" where
it is made): the text of the ``RuntimeError`` messages, which status ``startCapture`` without a
listener gives, what royale does when a Python listener raises (the double logs the traceback and
goes on, or stops the stream with ``DOUBLE.listener_error_policy = "stop"``), exposure-group
names, lens parameters, the minimum exposure time, the type of ``timeStamp`` (an object with
``count()`` like ``std::chrono::microseconds`` in 3.x/4.x, an ``int`` in 5.x). Use cases whose
raw layout is not documented (``MODE_MIXED_*``, ``Low_Noise_Extended``, ``Fast_Acquisition``)
are not offered.

The control surface for tests is the module-level :data:`DOUBLE` (a :class:`DoubleControl`);
nothing else in this module is meant to be touched by a test.
"""

from __future__ import annotations

import logging
import re
import threading
import time
import traceback
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

_log = logging.getLogger("roypy_double")

# -- CameraStatus (Status.hpp, royale 3.21 and 5.4) -------------------------------------------
CameraStatus_SUCCESS = 0
CameraStatus_RUNTIME_ERROR = 1024
CameraStatus_DISCONNECTED = 1026
CameraStatus_INVALID_VALUE = 1027
CameraStatus_TIMEOUT = 1028
CameraStatus_LOGIC_ERROR = 2048
CameraStatus_NOT_IMPLEMENTED = 2049
CameraStatus_OUT_OF_BOUNDS = 2050
CameraStatus_RESOURCE_ERROR = 4096
CameraStatus_FILE_NOT_FOUND = 4097
CameraStatus_COULD_NOT_OPEN = 4098
CameraStatus_DATA_NOT_FOUND = 4099
CameraStatus_DEVICE_IS_BUSY = 4100
CameraStatus_WRONG_DATA_FORMAT_FOUND = 4101
CameraStatus_USECASE_NOT_SUPPORTED = 5001
CameraStatus_FRAMERATE_NOT_SUPPORTED = 5002
CameraStatus_EXPOSURE_TIME_NOT_SUPPORTED = 5003
CameraStatus_DEVICE_NOT_INITIALIZED = 5004
CameraStatus_CALIBRATION_DATA_ERROR = 5005
CameraStatus_INSUFFICIENT_PRIVILEGES = 5006
CameraStatus_DEVICE_ALREADY_INITIALIZED = 5007
CameraStatus_EXPOSURE_MODE_INVALID = 5008
CameraStatus_NO_CALIBRATION_DATA = 5009
CameraStatus_INSUFFICIENT_BANDWIDTH = 5010
CameraStatus_DUTYCYCLE_NOT_SUPPORTED = 5011
CameraStatus_SPECTRE_NOT_INITIALIZED = 5012
CameraStatus_NO_USE_CASES = 5013
CameraStatus_NO_USE_CASES_FOR_LEVEL = 5014
CameraStatus_FSM_INVALID_TRANSITION = 8096
CameraStatus_UNKNOWN = 0x7FFFFF01

_STATUS_NAMES: dict[int, str] = {
    value: name[len("CameraStatus_") :]
    for name, value in list(globals().items())
    if name.startswith("CameraStatus_")
}

# -- other enums as roypy exposes them (module constants) ------------------------------------
CameraAccessLevel_L1 = 1
CameraAccessLevel_L2 = 2
CameraAccessLevel_L3 = 3
CameraAccessLevel_L4 = 4

CallbackData_None = 0
CallbackData_Raw = 1
CallbackData_Depth = 2
CallbackData_Intermediate = 4

ExposureMode_MANUAL = 0
ExposureMode_AUTOMATIC = 1

EventSeverity_ROYALE_INFO = 0
EventSeverity_ROYALE_WARNING = 1
EventSeverity_ROYALE_ERROR = 2
EventSeverity_ROYALE_FATAL = 3

EventType_ROYALE_CAPTURE_STREAM = 0
EventType_ROYALE_DEVICE_DISCONNECTED = 1
EventType_ROYALE_OVER_TEMPERATURE = 2
EventType_ROYALE_RAW_FRAME_STATS = 3

#: names that exist only from a given generation on (module attributes, via ``__getattr__``)
_MODULE_SINCE: dict[str, int] = {
    "IRawDataListener": 5,
    "PythonEventListener": 5,
    "ModulationScheme_MODULATION_SCHEME_NONE": 5,
    "ModulationScheme_MODULATION_SCHEME_CW": 5,
    "EventType_ROYALE_EYE_SAFETY": 5,
}

#: royale versions the double claims per generation (3.21.1.70: R321; 5.4.0.2112: SampleYOLO's
#: install path; the 4.x build number is the double's choice)
_VERSIONS: dict[int, tuple[int, int, int, int]] = {
    3: (3, 21, 1, 70),
    4: (4, 24, 0, 0),
    5: (5, 4, 0, 2112),
}

#: the pico flexx use cases whose raw layout follows from the name (old royale
#: ``OperationMode.hpp``: ``MODE_<raw frames>_<fps>FPS_<max exposure us>``, 9 = grey + 2 x 4,
#: 5 = grey + 4); in the order royale 3.21 lists them for a pico flexx
PICO_FLEXX_USE_CASES = (
    "MODE_9_5FPS_2000",
    "MODE_9_10FPS_1000",
    "MODE_9_15FPS_700",
    "MODE_9_25FPS_450",
    "MODE_5_35FPS_600",
    "MODE_5_45FPS_500",
)
#: modulation frequencies [Hz] of the raw frame sets (80.32 MHz first in the 9-frame modes)
FREQUENCIES_9 = (80_320_000, 60_240_000)
FREQUENCIES_5 = (60_240_000,)
SENSOR_WIDTH = 224
SENSOR_HEIGHT = 171
#: the pseudo-data row value of the 5.x flat buffer (double's choice: out of the 12-bit range,
#: so a row leaking into an image is obvious)
PSEUDO_WORD = 0xBEEF
DEFAULT_CAMERA_ID = "0007-0307-0107-2314"  # the id royale 3.21's sample printed (README)


def getStatusString(status: int) -> str:
    """The name of a ``CameraStatus`` (royale returns a sentence; the double the enum name)."""
    return _STATUS_NAMES.get(int(status), f"unknown status {int(status)}")


getErrorString = getStatusString


def getVersion() -> tuple[int, int, int, int]:
    """royale's version ``(major, minor, patch, build)`` for the simulated generation."""
    return _VERSIONS[DOUBLE.generation]


def getVersionString() -> str:
    """``"major.minor.patch.build"``, consistent with :func:`getVersion`."""
    return ".".join(str(v) for v in getVersion())


class RoyaleStatusError(RuntimeError):
    """Not a roypy name: what the double raises; a ``RuntimeError`` as roypy's errors are."""


def _fail(status: int, detail: str) -> int:
    """Raise (or, in ``status_mode == "return"``, return) a failing ``CameraStatus``."""
    if DOUBLE.status_mode == "return":
        return status
    raise RoyaleStatusError(f"{getStatusString(status)} ({status}): {detail}")


# -- SWIG-like containers ----------------------------------------------------------------------
class _Vector(list):  # type: ignore[type-arg]
    """A SWIG ``std::vector`` proxy: a list with ``size()``."""

    def size(self) -> int:
        return len(self)


class _Pair:
    """A SWIG ``Pair``: ``.first`` / ``.second`` and indexable."""

    def __init__(self, first: Any, second: Any) -> None:
        self.first = first
        self.second = second

    def __getitem__(self, i: int) -> Any:
        return (self.first, self.second)[i]

    def __len__(self) -> int:
        return 2


class _Microseconds:
    """``std::chrono::microseconds`` as the 3.x/4.x double gives ``timeStamp``: ``count()``."""

    def __init__(self, us: int) -> None:
        self._us = int(us)

    def count(self) -> int:
        return self._us

    def __repr__(self) -> str:
        return f"microseconds({self._us})"


class LensParamMap(dict):  # type: ignore[type-arg]
    """royale >= 4: ``getLensParameters()`` returns a dict-like map with ``size()``."""

    def size(self) -> int:
        return len(self)

    def asdict(self) -> dict[str, float]:
        return dict(self)


class LensParameters:
    """royale 3.x: the struct ``getLensParameters(param)`` fills (``LensParameters.hpp``)."""

    def __init__(self) -> None:
        self.principalPoint = _Pair(0.0, 0.0)
        self.focalLength = _Pair(0.0, 0.0)
        self.distortionTangential = _Pair(0.0, 0.0)
        self.distortionRadial = _Vector([0.0, 0.0, 0.0])


# -- listener base classes (SWIG directors) ----------------------------------------------------
class _Director:
    """A SWIG director base: subclasses must call ``super().__init__()``."""

    def __init__(self) -> None:
        self._roypy_director = True


def _check_director(listener: Any, base: type, what: str) -> None:
    if not isinstance(listener, base):
        raise TypeError(f"in method '{what}', argument 2 of type '{base.__name__} *'")
    if not getattr(listener, "_roypy_director", False):
        raise TypeError(
            f"in method '{what}': the {type(listener).__name__} was not initialised "
            "(call super().__init__() in its __init__, as the SWIG director needs)"
        )


class IDepthDataListener(_Director):
    """Override ``onNewData(self, data)`` (a :class:`_DepthData`)."""

    def onNewData(self, data: Any) -> None:
        raise NotImplementedError


class IExtendedDataListener(_Director):
    """Override ``onNewData(self, data)`` (an :class:`IExtendedData`); level 2."""

    def onNewData(self, data: Any) -> None:
        raise NotImplementedError


class _IRawDataListener(_Director):
    """royale 5: override ``onNewData(self, data)`` (a ``RawData``); level 1."""

    def onNewData(self, data: Any) -> None:
        raise NotImplementedError


class _PythonEventListener(_Director):
    """royale 5: override ``onEventPython(self, severity, description, type)``."""

    def onEventPython(self, severity: int, description: str, type: int) -> None:
        raise NotImplementedError


class IRecordStopListener(_Director):
    """Override ``onRecordingStopped(self, frameCount)``."""

    def onRecordingStopped(self, frameCount: int) -> None:
        raise NotImplementedError


# -- the data objects --------------------------------------------------------------------------
class _Expirable:
    """Data valid only during the callback (royale reuses the memory afterwards)."""

    _valid = True

    def _require_valid(self, what: str) -> None:
        if not self._valid:
            raise RuntimeError(
                f"roypy double: {what} called after onNewData returned; royale reuses the "
                "buffer, copy the data inside the callback"
            )


class _RawDataV3(_Expirable):
    """``royale::RawData`` as roypy 3.x/4.x exposes it (no ``rawData`` attribute)."""

    def __init__(self, frame: _RawFrameSet) -> None:
        self._frames = frame.frames
        self._fail = frame.fail if frame.fail == "getRawPhase" else ""
        self.width = frame.width
        self.height = frame.height
        self.streamId = frame.stream_id
        self.exposureGroupNames = _Vector(frame.group_names)
        self.rawFrameCount = _Vector(frame.raw_frame_count)
        self.modulationFrequencies = _Vector(frame.modulation_frequencies)
        self.exposureTimes = _Vector(frame.exposure_times)
        self.illuminationTemperature = float(frame.temperature_c)
        self.phaseAngles = _Vector(frame.phase_angles)
        self.illuminationEnabled = _Vector(frame.illumination_enabled)
        self.timeStamp: Any = _Microseconds(frame.timestamp_us)

    def getRawPhase(self, idx: int) -> _Vector:
        """Raw frame ``idx`` as ``width * height`` uint16 values; empty when out of range."""
        self._require_valid("getRawPhase")
        if self._fail:
            raise RuntimeError(f"roypy double: injected failure ({self._fail})")
        if not 0 <= idx < self._frames.shape[0]:
            return _Vector()
        return _Vector(self._frames[idx].ravel().tolist())


class _RawDataV5(_RawDataV3):
    """``royale::RawData`` of royale 5: a flat buffer with a pseudo-data row per raw frame."""

    def __init__(self, frame: _RawFrameSet, *, expose_flat: bool) -> None:
        super().__init__(frame)
        self.timeStamp = int(frame.timestamp_us)
        self.modulationScheme = _MODULATION_SCHEME_CW
        n, h, w = self._frames.shape
        flat = np.full((n, h + 1, w), PSEUDO_WORD, dtype=np.uint16)
        flat[:, 1:, :] = self._frames
        self._flat = flat.ravel()
        if expose_flat:  # the C++ member; 5.4's roypy does not expose it (see module doc)
            self.rawData = _Vector(self._flat.tolist())

    def getNumberOfRawFrames(self) -> int:
        return int(sum(self.rawFrameCount))

    def getPseudoData(self, idx: int) -> _Vector:
        """The pseudo-data row before raw frame ``idx`` (``width`` values)."""
        self._require_valid("getPseudoData")
        per = self.width * (self.height + 1)
        return _Vector(self._flat[idx * per : idx * per + self.width].tolist())

    def getRawPhase(self, idx: int) -> _Vector:
        """Raw frame ``idx`` read past its pseudo-data row (``RawData::getRawData(idx)``)."""
        self._require_valid("getRawPhase")
        if self._fail:
            raise RuntimeError(f"roypy double: injected failure ({self._fail})")
        if not 0 <= idx < self.getNumberOfRawFrames():
            return _Vector()
        per = self.width * (self.height + 1)
        start = idx * per + self.width
        return _Vector(self._flat[start : start + self.width * self.height].tolist())


_MODULATION_SCHEME_CW = 1  # roypy 5's ModulationScheme_MODULATION_SCHEME_CW (module __getattr__)


class _DepthData(_Expirable):
    """``royale::DepthData``: per-pixel points of a flat wall at ``DOUBLE.depth_m``."""

    def __init__(self, frame: _RawFrameSet, generation: int, lens: dict[str, float]) -> None:
        self.width = frame.width
        self.height = frame.height
        self.streamId = frame.stream_id
        self.exposureTimes = _Vector(frame.exposure_times)
        self.timeStamp: Any = (
            int(frame.timestamp_us) if generation >= 5 else _Microseconds(frame.timestamp_us)
        )
        self._generation = generation
        v, u = np.mgrid[0 : frame.height, 0 : frame.width].astype(np.float32)
        z = np.full(u.shape, DOUBLE.depth_m, dtype=np.float32)
        self._x = (u - lens["cx"]) / lens["fx"] * z
        self._y = (v - lens["cy"]) / lens["fy"] * z
        self._z = z
        grey = frame.frames[frame.grey_index].astype(np.float32)
        self._gray = grey
        if generation >= 5:
            self.illuminationTemperature = float(frame.temperature_c)

    def getNumPoints(self) -> int:
        return self.width * self.height

    def _at(self, array: np.ndarray, i: int) -> float:
        self._require_valid("DepthData access")
        return float(array.ravel()[i])

    def getX(self, i: int) -> float:
        return self._at(self._x, i)

    def getY(self, i: int) -> float:
        return self._at(self._y, i)

    def getZ(self, i: int) -> float:
        return self._at(self._z, i)

    def getGrayValue(self, i: int) -> int:
        return int(self._at(self._gray, i))

    def getDepthConfidence(self, i: int) -> float:
        """255 (uint8) before royale 5, 1.0 (float 0..1) from 5 on."""
        self._require_valid("getDepthConfidence")
        return 1.0 if self._generation >= 5 else 255

    def npoints(self) -> np.ndarray:
        """royale >= 4: (H, W, 6) x,y,z,noise,gray,conf; royale 5: (H, W, 5) x,y,z,gray,conf."""
        self._require_valid("npoints")
        if self._generation < 4:
            raise AttributeError("'DepthData' object has no attribute 'npoints' (royale 3.x)")
        conf = np.full(self._z.shape, 1.0 if self._generation >= 5 else 255.0, np.float32)
        channels = [self._x, self._y, self._z]
        if self._generation == 4:
            channels.append(np.zeros_like(self._z))
        channels += [self._gray, conf]
        return np.stack(channels, axis=-1)


class IExtendedData(_Expirable):
    """What ``IExtendedDataListener.onNewData`` receives (``IExtendedData.hpp``)."""

    def __init__(self, raw: _RawDataV3 | None, depth: _DepthData | None, fail: str) -> None:
        self._raw = raw
        self._depth = depth
        self._fail = fail

    def hasRawData(self) -> bool:
        self._require_valid("hasRawData")
        if self._fail:
            raise RuntimeError(f"roypy double: injected failure ({self._fail})")
        return self._raw is not None

    def getRawData(self) -> _RawDataV3 | None:
        self._require_valid("getRawData")
        return self._raw

    def hasDepthData(self) -> bool:
        return self._depth is not None

    def getDepthData(self) -> _DepthData | None:
        return self._depth

    def hasIntermediateData(self) -> bool:
        """Intermediate data is not simulated."""
        return False

    def getIntermediateData(self) -> None:
        return None


# -- what the stream delivers --------------------------------------------------------------------
@dataclass(frozen=True)
class UseCaseSpec:
    """A use case as the double streams it."""

    name: str
    frame_rate_hz: float
    max_exposure_us: int
    frequencies_hz: tuple[int, ...]

    @property
    def n_raw_frames(self) -> int:
        return 1 + 4 * len(self.frequencies_hz)


def use_case_spec(name: str) -> UseCaseSpec:
    """The raw layout of a ``MODE_<5|9>_<fps>FPS_<us>`` use case."""
    m = re.fullmatch(r"MODE_(5|9)_(\d+)FPS_(\d+)", name)
    if m is None:
        raise ValueError(f"roypy double: no raw layout known for use case {name!r}")
    freqs = FREQUENCIES_9 if m.group(1) == "9" else FREQUENCIES_5
    return UseCaseSpec(name, float(m.group(2)), int(m.group(3)), freqs)


@dataclass(frozen=True)
class RawSlot:
    """One raw frame of a delivery, in delivery order.

    ``frequency_index`` is -1 for the grey frame; ``phase_step`` = phase angle / 90 (0 for grey).
    """

    position: int
    grey: bool
    frequency_index: int
    frequency_hz: int
    phase_deg: int
    exposure_us: int

    @property
    def phase_step(self) -> int:
        return self.phase_deg // 90


if TYPE_CHECKING:  # a runtime alias would need Python 3.9 (collections.abc generics)
    #: provider(use case, frame index, slots in delivery order) -> one (H, W) uint16 image
    #: per slot
    FrameProvider = Callable[[UseCaseSpec, int, Sequence[RawSlot]], Sequence[np.ndarray]]


def pattern_value(frame_index: int, slot: RawSlot) -> int:
    """The default provider's value at even columns (odd columns hold this + 1).

    Grey: ``3000 + frame_index % 32``; phase frame: ``1024 + 256 * frequency_index +
    64 * phase_step + frame_index % 32``. All within 12 bits, all distinct per frame.
    """
    if slot.grey:
        return 3000 + frame_index % 32
    return 1024 + 256 * slot.frequency_index + 64 * slot.phase_step + frame_index % 32


def pattern_provider(
    use_case: UseCaseSpec, frame_index: int, slots: Sequence[RawSlot]
) -> list[np.ndarray]:
    """The deterministic default frame provider (see :func:`pattern_value`)."""
    columns = (np.arange(SENSOR_WIDTH, dtype=np.uint16) % 2)[None, :]
    base = np.broadcast_to(columns, (SENSOR_HEIGHT, SENSOR_WIDTH))
    return [(base + np.uint16(pattern_value(frame_index, s))).astype(np.uint16) for s in slots]


@dataclass
class _RawFrameSet:
    """Everything one delivery carries, before it is wrapped per generation."""

    frames: np.ndarray
    width: int
    height: int
    grey_index: int
    group_names: list[str]
    raw_frame_count: list[int]
    modulation_frequencies: list[int]
    exposure_times: list[int]
    phase_angles: list[int]
    illumination_enabled: list[int]
    temperature_c: float
    timestamp_us: int
    stream_id: int
    fail: str


def _slots(spec: UseCaseSpec, exposure_us: int) -> list[RawSlot]:
    phase_slots = []
    for k, f in enumerate(spec.frequencies_hz):
        for deg in DOUBLE.phase_order:
            phase_slots.append(RawSlot(0, False, k, f, int(deg), exposure_us))
    grey = RawSlot(0, True, -1, spec.frequencies_hz[-1], 0, exposure_us)
    ordered = [*phase_slots, grey] if DOUBLE.grey_last else [grey, *phase_slots]
    return [
        RawSlot(i, s.grey, s.frequency_index, s.frequency_hz, s.phase_deg, s.exposure_us)
        for i, s in enumerate(ordered)
    ]


def _build_frame_set(spec: UseCaseSpec, index: int, exposure_us: int, fail: str) -> _RawFrameSet:
    slots = _slots(spec, exposure_us)
    images = DOUBLE.frame_provider(spec, index, slots)
    frames = np.stack(
        [np.asarray(im, dtype=np.uint16).reshape(SENSOR_HEIGHT, SENSOR_WIDTH) for im in images]
    )
    if frames.shape[0] != len(slots):
        raise ValueError(f"frame provider gave {frames.shape[0]} images for {len(slots)} slots")
    groups: list[tuple[str, int, int]] = []  # name, count, frequency
    for s in slots:
        name = "gray" if s.grey else f"mod{s.frequency_hz // 10_000}"
        if groups and groups[-1][0] == name:
            groups[-1] = (name, groups[-1][1] + 1, s.frequency_hz)
        else:
            groups.append((name, 1, s.frequency_hz))
    if DOUBLE.values_per == "frame":
        freqs = [s.frequency_hz for s in slots]
        exposures = [s.exposure_us for s in slots]
    else:  # "for each sequence" = exposure group
        freqs = [g[2] for g in groups]
        exposures = [exposure_us for _ in groups]
    grey_index = next(s.position for s in slots if s.grey)
    return _RawFrameSet(
        frames=frames,
        width=SENSOR_WIDTH,
        height=SENSOR_HEIGHT,
        grey_index=grey_index,
        group_names=[g[0] for g in groups],
        raw_frame_count=[g[1] for g in groups],
        modulation_frequencies=freqs,
        exposure_times=exposures,
        phase_angles=[s.phase_deg for s in slots],
        illumination_enabled=[0 if s.grey else 1 for s in slots],
        temperature_c=float(DOUBLE.illumination_temperature(index)),
        timestamp_us=int(time.time() * 1e6),
        stream_id=DOUBLE.stream_id,
        fail=fail,
    )


# -- the control surface -------------------------------------------------------------------------
@dataclass
class PluggedCamera:
    """A camera on the simulated bus."""

    camera_id: str
    name: str = "PICOFLEXX"
    use_cases: tuple[str, ...] = PICO_FLEXX_USE_CASES
    unplug_after_frames: int | None = None
    connected: bool = True


class DoubleControl:
    """The test-facing control of the double (not part of roypy). One instance: :data:`DOUBLE`.

    Attributes
    ----------
    generation : int
        3, 4 or 5: which roypy surface the module shows (see the module docstring).
    access_codes : dict[str, int]
        Access code -> level; :data:`L2_CODE` gives level 2. Any other code gives level 1.
    grey_last : bool
        The grey raw frame after the phase frames (royale's IntensityPhaseOrder), else first.
    phase_order : tuple of int
        Phase angles [deg] in delivery order within each four-phase set.
    values_per : str
        ``"group"``: ``modulationFrequencies`` / ``exposureTimes`` per exposure group ("for each
        sequence", the default), ``"frame"``: per raw frame.
    frame_provider : FrameProvider
        Images per raw frame; :func:`pattern_provider` by default.
    illumination_temperature : callable
        frame index -> ``illuminationTemperature`` [degC].
    frame_interval_s : float or None
        Time between deliveries; None = 1 / the use case's frame rate.
    status_mode : str
        ``"raise"`` (failing calls raise ``RuntimeError``) or ``"return"`` (they return the
        non-zero ``CameraStatus``).
    listener_error_policy : str
        A client listener raising: ``"log"`` (log, count in ``listener_errors``, go on) or
        ``"stop"`` (the stream dies, as a crashed capture thread would).
    expose_flat_raw_data : bool
        royale 5: also expose the flat ``rawData`` buffer (with its pseudo-data rows).
    depth_m : float
        The depth of the flat wall the depth listener sees.
    lens : dict
        fx, fy, cx, cy, k1, k2, p1, p2, k3 (double's choice of values).
    stream_id : int
    listener_errors : list of str
        Tracebacks of client listeners that raised.
    events : list of tuple
        (camera id, severity, description, type) of every event the double sent.
    devices : list
        Every camera device object created since the last :meth:`reset`.
    """

    L2_CODE = "roypy-double-level-2"
    L3_CODE = "roypy-double-level-3"

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self.reset()

    def reset(self, generation: int = 5) -> None:
        """Back to the defaults: no camera plugged, grey first, the pattern provider."""
        if generation not in _VERSIONS:
            raise ValueError(f"generation {generation!r}; one of 3, 4, 5")
        old = list(getattr(self, "devices", []))
        for dev in old:  # stop streams of a previous test
            dev._halt()
        self.generation = generation
        self.access_codes: dict[str, int] = {self.L2_CODE: 2, self.L3_CODE: 3}
        self.cameras: dict[str, PluggedCamera] = {}
        self.grey_last = False
        self.phase_order: tuple[int, ...] = (0, 90, 180, 270)
        self.values_per = "group"
        self.frame_provider: FrameProvider = pattern_provider
        self.illumination_temperature: Callable[[int], float] = lambda i: 30.0 + 0.25 * (i % 8)
        self.frame_interval_s: float | None = None
        self.status_mode = "raise"
        self.listener_error_policy = "log"
        self.expose_flat_raw_data = False
        self.depth_m = 1.0
        self.lens: dict[str, float] = dict(
            fx=210.0, fy=210.0, cx=111.5, cy=85.0, k1=0.0, k2=0.0, p1=0.0, p2=0.0, k3=0.0
        )
        self.stream_id = 0
        self.listener_errors: list[str] = []
        self.events: list[tuple[str, int, str, int]] = []
        self.devices: list[_CameraDevice] = []
        self._fail_next: list[str] = []

    # cameras on the bus
    def plug(
        self,
        camera_id: str = DEFAULT_CAMERA_ID,
        *,
        name: str = "PICOFLEXX",
        use_cases: Sequence[str] = PICO_FLEXX_USE_CASES,
        unplug_after_frames: int | None = None,
    ) -> PluggedCamera:
        """Connect a camera; ``unplug_after_frames`` pulls it after that many deliveries."""
        for uc in use_cases:
            use_case_spec(uc)  # only use cases with a known raw layout
        cam = PluggedCamera(camera_id, name, tuple(use_cases), unplug_after_frames)
        with self._lock:
            self.cameras[camera_id] = cam
        return cam

    def unplug(self, camera_id: str = DEFAULT_CAMERA_ID) -> None:
        """Pull the camera: its stream stops, its device objects fail from now on."""
        with self._lock:
            cam = self.cameras.pop(camera_id, None)
            if cam is not None:
                cam.connected = False
            devices = [d for d in self.devices if d._plugged is cam]
        for dev in devices:
            dev._disconnected()

    # fault injection
    def fail_next_data(self, n: int = 1, where: str = "getRawPhase") -> None:
        """The next ``n`` deliveries carry data that raises ``RuntimeError`` when read.

        ``where``: ``"getRawPhase"`` (the raw data object) or ``"hasRawData"`` (the 3.x/4.x
        ``IExtendedData`` wrapper).
        """
        if where not in ("getRawPhase", "hasRawData"):
            raise ValueError(f"where={where!r}")
        with self._lock:
            self._fail_next.extend([where] * n)

    def _take_failure(self) -> str:
        with self._lock:
            return self._fail_next.pop(0) if self._fail_next else ""

    def access_level(self, code: str | None) -> int:
        return self.access_codes.get(code or "", 1)


#: the one control of the double
DOUBLE = DoubleControl()


# -- CameraManager and the camera device ---------------------------------------------------------
class CameraManager:
    """``roypy.CameraManager(activationCode="")``: lists cameras, creates devices."""

    def __init__(self, activationCode: str = "") -> None:
        self._code = activationCode or ""

    @staticmethod
    def getAccessLevel(activationCode: str) -> int:
        return DOUBLE.access_level(activationCode)

    def getConnectedCameraList(self) -> _Vector:
        """Ids of the plugged cameras; an empty vector when there is none (no exception)."""
        with DOUBLE._lock:
            return _Vector(DOUBLE.cameras)

    def getConnectedCameraNames(self) -> _Vector:
        with DOUBLE._lock:
            return _Vector(c.name for c in DOUBLE.cameras.values())

    def createCamera(self, cameraId: str) -> _CameraDevice:
        """A device for a listed id (``.rrf`` replay is not simulated)."""
        with DOUBLE._lock:
            cam = DOUBLE.cameras.get(str(cameraId))
        if cam is None:
            _fail(CameraStatus_COULD_NOT_OPEN, f"no camera {cameraId!r} (double)")
            return None  # type: ignore[return-value]  # status_mode "return"
        dev = _CameraDevice(cam, DOUBLE.access_level(self._code))
        with DOUBLE._lock:
            DOUBLE.devices.append(dev)
        return dev


#: device methods that exist only from a given generation on
_DEVICE_SINCE: dict[str, int] = {
    "registerRawDataListener": 5,
    "unregisterRawDataListener": 5,
    "asReplay": 4,
    "isDepthSupported": 5,
}

_in_callback = threading.local()


class _CameraDevice:
    """``roypy.ICameraDevice`` for one plugged camera."""

    def __init__(self, plugged: PluggedCamera, access_level: int) -> None:
        self._plugged = plugged
        self._level = access_level
        self._initialized = False
        self._use_case = ""
        self._exposure_us: int | None = None
        self._exposure_mode = ExposureMode_MANUAL
        self._callback_data = CallbackData_Depth
        self._pending_callback_data: int | None = None
        self._depth_listener: Any = None
        self._extended_listener: Any = None
        self._raw_listener: Any = None
        self._event_listener: Any = None
        self._record_listener: Any = None
        self._recording: tuple[str, int] | None = None
        self._recorded = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self.frames_delivered = 0

    def __getattribute__(self, name: str) -> Any:
        since = _DEVICE_SINCE.get(name)
        if since is not None and DOUBLE.generation < since:
            raise AttributeError(f"'ICameraDevice' object has no attribute {name!r}")
        return object.__getattribute__(self, name)

    # -- helpers
    def _enter(self, what: str, *, init: bool = True, level: int = 1) -> int:
        """0 when the call may proceed, else the failing status (raised in "raise" mode)."""
        if getattr(_in_callback, "active", False):
            return _fail(
                CameraStatus_LOGIC_ERROR,
                f"{what} called from inside a royale callback (not allowed)",
            )
        if not self._plugged.connected:
            return _fail(CameraStatus_DISCONNECTED, f"{what}: the camera is disconnected")
        if init and not self._initialized:
            return _fail(CameraStatus_DEVICE_NOT_INITIALIZED, f"{what}: call initialize() first")
        if self._level < level:
            return _fail(
                CameraStatus_INSUFFICIENT_PRIVILEGES,
                f"{what} needs access level {level}; the CameraManager was given a code of "
                f"level {self._level}",
            )
        return CameraStatus_SUCCESS

    @property
    def _spec(self) -> UseCaseSpec:
        return use_case_spec(self._use_case)

    # -- level 1: identity and use cases
    def initialize(self, useCase: str = "") -> int:
        status = self._enter("initialize", init=False)
        if status:
            return status
        if self._initialized:
            return _fail(CameraStatus_DEVICE_ALREADY_INITIALIZED, "initialize called twice")
        name = useCase or self._plugged.use_cases[0]  # "sets the first available use case"
        if name not in self._plugged.use_cases:
            return _fail(CameraStatus_USECASE_NOT_SUPPORTED, f"use case {name!r}")
        self._initialized = True
        self._use_case = name
        return CameraStatus_SUCCESS

    def getId(self) -> str:
        self._enter("getId", init=False)
        return self._plugged.camera_id

    def getCameraName(self) -> str:
        self._enter("getCameraName")
        return self._plugged.name

    def getCameraInfo(self) -> _Vector:
        """Key/value tuples (the royale 3.21 pico flexx example in the notes)."""
        self._enter("getCameraInfo")
        return _Vector(
            [
                ("BRIDGE_TYPE", "Enclustra"),
                ("MODULE_IDENTIFIER", "00000000"),
                ("MODULE_SERIAL", "0"),
                ("IMAGER", "M2450_A12_AIO"),
                ("PROCESSING_NAME", "Spectre"),
            ]
        )

    def getMaxSensorWidth(self) -> int:
        self._enter("getMaxSensorWidth")
        return SENSOR_WIDTH

    def getMaxSensorHeight(self) -> int:
        self._enter("getMaxSensorHeight")
        return SENSOR_HEIGHT

    def getUseCases(self) -> _Vector:
        self._enter("getUseCases")
        return _Vector(self._plugged.use_cases)

    def getNumberOfStreams(self, useCaseName: str) -> int:
        self._enter("getNumberOfStreams")
        if useCaseName not in self._plugged.use_cases:
            _fail(CameraStatus_USECASE_NOT_SUPPORTED, f"use case {useCaseName!r}")
        return 1

    def getCurrentUseCase(self) -> str:
        self._enter("getCurrentUseCase")
        return self._use_case

    def setUseCase(self, name: str) -> int:
        """Allowed while capturing (royale's roypy tests do so); the stream switches."""
        status = self._enter("setUseCase")
        if status:
            return status
        if name not in self._plugged.use_cases:
            return _fail(
                CameraStatus_USECASE_NOT_SUPPORTED,
                f"use case {name!r} is not one of {list(self._plugged.use_cases)}",
            )
        with self._lock:
            self._use_case = name
            self._exposure_us = None
        return CameraStatus_SUCCESS

    def getFrameRate(self) -> int:
        self._enter("getFrameRate")
        return int(self._spec.frame_rate_hz)

    getMaxFrameRate = getFrameRate

    # -- exposure
    def getExposureLimits(self, streamId: int = 0) -> _Pair:
        """(min, max) in us; max from the use case name, min = 1 (double's choice)."""
        self._enter("getExposureLimits")
        return _Pair(1, self._spec.max_exposure_us)

    def setExposureTime(self, exposureTime: int, streamId: int = 0) -> int:
        status = self._enter("setExposureTime")
        if status:
            return status
        if self._exposure_mode != ExposureMode_MANUAL:
            return _fail(CameraStatus_EXPOSURE_MODE_INVALID, "exposure mode is AUTOMATIC")
        if not 1 <= int(exposureTime) <= self._spec.max_exposure_us:
            return _fail(
                CameraStatus_EXPOSURE_TIME_NOT_SUPPORTED,
                f"{exposureTime} us outside 1..{self._spec.max_exposure_us}",
            )
        with self._lock:
            self._exposure_us = int(exposureTime)
        return CameraStatus_SUCCESS

    def setExposureMode(self, exposureMode: int, streamId: int = 0) -> int:
        status = self._enter("setExposureMode")
        if status:
            return status
        self._exposure_mode = int(exposureMode)
        return CameraStatus_SUCCESS

    def getExposureMode(self, streamId: int = 0) -> int:
        self._enter("getExposureMode")
        return self._exposure_mode

    # -- lens
    def getLensParameters(self, *param: Any) -> Any:
        """royale 3.x: fills the ``LensParameters`` passed in; royale >= 4: a ``LensParamMap``."""
        self._enter("getLensParameters")
        lens = DOUBLE.lens
        if DOUBLE.generation < 4:
            if len(param) != 1:
                raise TypeError("getLensParameters() takes exactly 2 arguments (1 given)")
            p = param[0]
            p.principalPoint = _Pair(lens["cx"], lens["cy"])
            p.focalLength = _Pair(lens["fx"], lens["fy"])
            p.distortionTangential = _Pair(lens["p1"], lens["p2"])
            p.distortionRadial = _Vector([lens["k1"], lens["k2"], lens["k3"]])
            return CameraStatus_SUCCESS
        if param:
            raise TypeError("getLensParameters() takes exactly 1 argument (2 given)")
        return LensParamMap(lens)

    # -- state
    def isConnected(self) -> bool:
        return self._plugged.connected

    def isCalibrated(self) -> bool:
        self._enter("isCalibrated")
        return True

    def isCapturing(self) -> bool:
        thread = self._thread
        return self._plugged.connected and thread is not None and thread.is_alive()

    def getAccessLevel(self) -> int:
        return self._level

    def asReplay(self) -> Any:
        """royale >= 4: a live camera is not a replay -> ``SystemError``."""
        raise SystemError("this camera device is not a replay")

    # -- listeners
    def registerDataListener(self, listener: Any) -> int:
        status = self._enter("registerDataListener")
        if status:
            return status
        _check_director(listener, IDepthDataListener, "ICameraDevice_registerDataListener")
        self._depth_listener = weakref.ref(listener)  # roypy keeps no reference (quirk 1)
        return CameraStatus_SUCCESS

    def unregisterDataListener(self) -> int:
        self._depth_listener = None
        return CameraStatus_SUCCESS

    def registerDataListenerExtended(self, listener: Any) -> int:
        """Level 2 (``ICameraDevice.hpp``); without a level-2 code: INSUFFICIENT_PRIVILEGES."""
        status = self._enter("registerDataListenerExtended", level=2)
        if status:
            return status
        _check_director(
            listener, IExtendedDataListener, "ICameraDevice_registerDataListenerExtended"
        )
        self._extended_listener = weakref.ref(listener)
        return CameraStatus_SUCCESS

    def unregisterDataListenerExtended(self) -> int:
        self._extended_listener = None
        return CameraStatus_SUCCESS

    def registerRawDataListener(self, listener: Any) -> int:
        """royale 5, level 1 (``ICameraDevice.hpp`` 5.4)."""
        status = self._enter("registerRawDataListener")
        if status:
            return status
        _check_director(listener, _IRawDataListener, "ICameraDevice_registerRawDataListener")
        self._raw_listener = weakref.ref(listener)
        return CameraStatus_SUCCESS

    def unregisterRawDataListener(self) -> int:
        self._raw_listener = None
        return CameraStatus_SUCCESS

    def registerEventListener(self, listener: Any) -> int:
        """royale 5: a ``PythonEventListener``; 3.x/4.x have no Python event director."""
        status = self._enter("registerEventListener")
        if status:
            return status
        if DOUBLE.generation < 5:
            raise TypeError(
                "in method 'ICameraDevice_registerEventListener': roypy before royale 5 has no "
                "Python-subclassable event listener (poll isConnected())"
            )
        _check_director(listener, _PythonEventListener, "ICameraDevice_registerEventListener")
        self._event_listener = weakref.ref(listener)
        return CameraStatus_SUCCESS

    def unregisterEventListener(self) -> int:
        self._event_listener = None
        return CameraStatus_SUCCESS

    def setCallbackData(self, cbData: int) -> int:
        """Level 2; effective at the next ``startCapture`` (``ICameraDevice.hpp`` 5.4)."""
        status = self._enter("setCallbackData", init=False, level=2)
        if status:
            return status
        with self._lock:
            if self.isCapturing():
                self._pending_callback_data = int(cbData)
            else:
                self._callback_data = int(cbData)
        return CameraStatus_SUCCESS

    # -- recording
    def registerRecordListener(self, listener: Any) -> int:
        status = self._enter("registerRecordListener")
        if status:
            return status
        _check_director(listener, IRecordStopListener, "ICameraDevice_registerRecordListener")
        self._record_listener = weakref.ref(listener)
        return CameraStatus_SUCCESS

    def unregisterRecordListener(self) -> int:
        self._record_listener = None
        return CameraStatus_SUCCESS

    def startRecording(
        self, fileName: str, numberOfFrames: int = 0, frameSkip: int = 0, msSkip: int = 0
    ) -> int:
        """Writes a placeholder file (not an .rrf); stops itself after ``numberOfFrames``."""
        status = self._enter("startRecording")
        if status:
            return status
        with open(fileName, "w") as f:
            f.write("roypy double recording placeholder (not an rrf)\n")
        with self._lock:
            self._recording = (fileName, int(numberOfFrames))
            self._recorded = 0
        return CameraStatus_SUCCESS

    def stopRecording(self) -> int:
        status = self._enter("stopRecording")
        if status:
            return status
        self._finish_recording()
        return CameraStatus_SUCCESS

    def _finish_recording(self) -> None:
        with self._lock:
            if self._recording is None:
                return
            self._recording = None
            count = self._recorded
        listener = self._record_listener() if self._record_listener else None
        if listener is not None:
            self._call_listener(listener.onRecordingStopped, count)

    # -- capture
    def startCapture(self) -> int:
        status = self._enter("startCapture")
        if status:
            return status
        if not (self._depth_listener or self._extended_listener or self._raw_listener):
            # the header: "If no data listener is registered an error will be returned";
            # which status is the double's choice
            return _fail(CameraStatus_LOGIC_ERROR, "startCapture: no data listener registered")
        with self._lock:
            if self.isCapturing():
                return CameraStatus_SUCCESS
            if self._pending_callback_data is not None:
                self._callback_data = self._pending_callback_data
                self._pending_callback_data = None
            self._stop = threading.Event()
            self._thread = threading.Thread(
                target=self._run, args=(self._stop,), name="roypy-double-capture", daemon=True
            )
            self._thread.start()
        return CameraStatus_SUCCESS

    def stopCapture(self) -> int:
        status = self._enter("stopCapture")
        if status:
            return status
        self._halt()
        if self._pending_callback_data is not None:
            self._callback_data = self._pending_callback_data
            self._pending_callback_data = None
        return CameraStatus_SUCCESS

    def _halt(self) -> None:
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(5.0)

    def _disconnected(self) -> None:
        """The camera was pulled: stop the stream, tell a 5.x event listener."""
        self._stop.set()
        listener = self._event_listener() if self._event_listener else None
        DOUBLE.events.append(
            (
                self._plugged.camera_id,
                EventSeverity_ROYALE_FATAL,
                "device disconnected",
                EventType_ROYALE_DEVICE_DISCONNECTED,
            )
        )
        if listener is not None:
            self._call_listener(
                listener.onEventPython,
                EventSeverity_ROYALE_FATAL,
                f"camera {self._plugged.camera_id} disconnected",
                EventType_ROYALE_DEVICE_DISCONNECTED,
            )

    def _call_listener(self, fn: Callable[..., Any], *args: Any) -> bool:
        """Call a client callback; False when it raised (logged, counted, policy applied)."""
        _in_callback.active = True
        try:
            fn(*args)
            return True
        except Exception:
            text = traceback.format_exc()
            DOUBLE.listener_errors.append(text)
            _log.error("roypy double: a listener raised:\n%s", text)
            if DOUBLE.listener_error_policy == "stop":
                self._stop.set()
            return False
        finally:
            _in_callback.active = False

    def _run(self, stop: threading.Event) -> None:
        """The capture thread: one delivery per frame interval until stopped or unplugged."""
        next_at = time.monotonic()
        while not stop.is_set():
            with self._lock:
                spec = self._spec
                exposure = self._exposure_us or spec.max_exposure_us
            interval = DOUBLE.frame_interval_s
            next_at += interval if interval is not None else 1.0 / spec.frame_rate_hz
            if stop.wait(max(0.0, next_at - time.monotonic())):
                break
            if not self._plugged.connected:
                break
            self._deliver(spec, exposure)
            limit = self._plugged.unplug_after_frames
            if limit is not None and self.frames_delivered >= limit:
                DOUBLE.unplug(self._plugged.camera_id)
                break

    def _deliver(self, spec: UseCaseSpec, exposure_us: int) -> None:
        index = self.frames_delivered
        self.frames_delivered += 1
        frame = _build_frame_set(spec, index, exposure_us, DOUBLE._take_failure())
        generation = DOUBLE.generation
        depth_listener = self._depth_listener() if self._depth_listener else None
        ext_listener = self._extended_listener() if self._extended_listener else None
        want_depth = self._callback_data != CallbackData_Raw and (
            depth_listener is not None or ext_listener is not None
        )
        depth = _DepthData(frame, generation, DOUBLE.lens) if want_depth else None
        objects: list[_Expirable] = [] if depth is None else [depth]
        if depth_listener is not None and depth is not None:
            self._call_listener(depth_listener.onNewData, depth)
        if generation >= 5:
            raw_listener = self._raw_listener() if self._raw_listener else None
            if raw_listener is not None:
                raw = _RawDataV5(frame, expose_flat=DOUBLE.expose_flat_raw_data)
                objects.append(raw)
                self._call_listener(raw_listener.onNewData, raw)
            ext_raw: _RawDataV3 | None = None  # 5.x IExtendedData carries no raw data
        else:
            ext_raw = _RawDataV3(frame)
            objects.append(ext_raw)
        if ext_listener is not None and (ext_raw is not None or depth is not None):
            fail = frame.fail if frame.fail == "hasRawData" else ""
            ext = IExtendedData(ext_raw, depth, fail)
            objects.append(ext)
            self._call_listener(ext_listener.onNewData, ext)
        for obj in objects:  # royale reuses the buffers after the callback
            obj._valid = False
        with self._lock:
            done = False
            if self._recording is not None:
                self._recorded += 1
                done = 0 < self._recording[1] <= self._recorded
        if done:
            self._finish_recording()


def __getattr__(name: str) -> Any:
    """Generation-dependent module names (PEP 562): absent where that roypy lacks them."""
    since = _MODULE_SINCE.get(name)
    if since is None:
        if name == "RawData":
            return _RawDataV5 if DOUBLE.generation >= 5 else _RawDataV3
        raise AttributeError(f"module 'roypy' has no attribute {name!r}")
    if DOUBLE.generation < since:
        raise AttributeError(
            f"module 'roypy' has no attribute {name!r} (royale {getVersionString()})"
        )
    return {
        "IRawDataListener": _IRawDataListener,
        "PythonEventListener": _PythonEventListener,
        "ModulationScheme_MODULATION_SCHEME_NONE": 0,
        "ModulationScheme_MODULATION_SCHEME_CW": _MODULATION_SCHEME_CW,
        "EventType_ROYALE_EYE_SAFETY": 4,
    }[name]


# -- a self-check for a numpy-only environment (``python roypy.py``) -----------------------------
def _self_check(interval_s: float = 0.005) -> None:
    """Stream every generation, use case and grey order through roypy's documented calls.

    Checks the raw layout (groups, angles, frequencies, pattern values), the illumination
    temperature, a listener that raises, and an unplug mid-stream. Raises AssertionError.
    """
    import queue

    _log.disabled = True  # the listener raising on purpose is logged otherwise
    for generation in (3, 4, 5):
        for grey_last in (False, True):
            for use_case in ("MODE_5_45FPS_500", "MODE_9_5FPS_2000"):
                DOUBLE.reset(generation=generation)
                DOUBLE.frame_interval_s = interval_s
                DOUBLE.grey_last = grey_last
                DOUBLE.illumination_temperature = lambda i: 25.0 + i
                DOUBLE.plug()
                got: queue.Queue[Any] = queue.Queue()
                calls = [0]

                def on_raw(raw: Any, got: Any = got, calls: list[int] = calls) -> None:
                    calls[0] += 1
                    if calls[0] == 1:
                        raise ValueError("first callback raises on purpose")
                    n = int(sum(raw.rawFrameCount))
                    images = [np.asarray(raw.getRawPhase(i)) for i in range(n)]
                    got.put((list(raw.phaseAngles), list(raw.rawFrameCount),
                             list(raw.modulationFrequencies), [int(im[0]) for im in images],
                             raw.illuminationTemperature))  # fmt: skip

                mgr = CameraManager(DOUBLE.L2_CODE)
                ids = mgr.getConnectedCameraList()
                assert ids.size() == 1
                cam = mgr.createCamera(ids[0])
                cam.initialize()
                if generation >= 5:

                    class RawL(_IRawDataListener):
                        def onNewData(self, data: Any) -> None:
                            on_raw(data)

                    listener: Any = RawL()
                    cam.registerRawDataListener(listener)
                else:

                    class ExtL(IExtendedDataListener):
                        def onNewData(self, data: Any) -> None:
                            if data.hasRawData():
                                on_raw(data.getRawData())

                    listener = ExtL()
                    cam.registerDataListenerExtended(listener)
                cam.setUseCase(use_case)
                cam.startCapture()
                angles, counts, freqs, values, temperature = got.get(timeout=5)
                spec = use_case_spec(use_case)
                n_f = len(spec.frequencies_hz)
                assert counts == ([4] * n_f + [1] if grey_last else [1] + [4] * n_f), counts
                grey_at = len(angles) - 1 if grey_last else 0
                assert values[grey_at] == 3000 + 1, values  # delivery 1 (0 raised)
                phase_values = [v for i, v in enumerate(values) if i != grey_at]
                assert phase_values == [
                    1024 + 256 * k + 64 * s + 1 for k in range(n_f) for s in range(4)
                ], phase_values
                assert len(freqs) == len(counts) and temperature == 26.0
                assert len(DOUBLE.listener_errors) == 1
                DOUBLE.unplug()
                if cam._thread is not None:  # a delivery in flight may still complete
                    cam._thread.join(5.0)
                while not got.empty():
                    got.get_nowait()
                time.sleep(10 * interval_s)
                assert got.empty() and not cam.isConnected() and not cam.isCapturing()
                try:
                    cam.stopCapture()
                except RuntimeError as exc:
                    assert "DISCONNECTED" in str(exc)
                else:
                    raise AssertionError("stopCapture on an unplugged camera did not fail")
                if generation >= 5:
                    assert DOUBLE.events[-1][3] == EventType_ROYALE_DEVICE_DISCONNECTED
    DOUBLE.reset()
    _log.disabled = False


if __name__ == "__main__":
    _self_check()
    import sys

    print(f"roypy double self-check: ok (Python {sys.version.split()[0]}, numpy {np.__version__})")
