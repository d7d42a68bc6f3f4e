"""Streaming from a real pico flexx through PMD's royale SDK (Python module ``roypy``), in this
process.

``roypy`` ships with royale (``<royale>/python``, not on PyPI). This module imports without it:
:func:`royale_available` says whether it is there, and :class:`RoyaleCamera` raises
:class:`RoyaleNotInstalledError` ("royale not installed", with the fix) when it is not. royale
is often built for another Python than the service's; then the camera bridge
(:mod:`toftwin_camera_bridge`, :class:`drivers.camera.bridge_client.BridgeCamera`) runs the very
same royale source in a process of its own.

royale's raw data, as we use it (sources in ``docs/devices.md``, "Camera (USB)")
-------------------------------------------------------------------------------
- A listener receives ``royale::RawData``: royale >= 5 through ``IRawDataListener`` /
  ``ICameraDevice.registerRawDataListener`` (level 1); earlier versions through
  ``IExtendedDataListener`` / ``registerDataListenerExtended`` (access level 2, an access code
  given to ``CameraManager``), where ``data.hasRawData()`` / ``data.getRawData()`` hold it.
  royale's sample ``sample_raw_data.py`` reads it exactly so
  (:class:`toftwin_camera_bridge.RoyaleSource`).
- ``RawData`` fields: ``timeStamp`` (microseconds since 1970 in royale >= 3.x headers),
  ``streamId``, ``width``, ``height``, ``rawData`` (uint16 words), ``exposureGroupNames``,
  ``rawFrameCount`` (raw frames per exposure group), ``modulationFrequencies`` and
  ``exposureTimes`` ("for each sequence"), ``illuminationTemperature``, ``phaseAngles`` and
  ``illuminationEnabled`` (per raw frame). ``getRawPhase(i)`` returns raw frame ``i``
  (``width * height`` words); in the flat ``rawData`` buffer every raw frame is preceded by one
  row of pseudo data (``getRawData(idx)`` = ``&rawData[idx * width * (height + 1) + width]``):
  :func:`toftwin_camera_bridge.copy_roypy_raw_data` copies it in the callback.
- The conversion to our frames: :func:`drivers.camera.royale_convert.royale_to_raw_frame`.
"""

from __future__ import annotations

from typing import Any

from drivers.camera.protocol import CameraError
from drivers.camera.royale_convert import RoyaleDataError, royale_to_raw_frame
from drivers.camera.source_camera import SourceCamera
from drivers.camera.wire import UseCase
from toftwin_camera_bridge import (
    INSTALL_HINT,
    RawDataCopy,
    RoyaleSource,
    copy_roypy_raw_data,
    split_raw_buffer,
)

try:  # royale's Python wrapper; absent on most machines (not on PyPI)
    import roypy  # type: ignore[import-not-found]

    _IMPORT_ERROR: str | None = None
except ImportError as exc:  # pragma: no cover - depends on the machine
    roypy = None
    _IMPORT_ERROR = str(exc)

__all__ = [
    "INSTALL_HINT",
    "RawDataCopy",
    "RoyaleCamera",
    "RoyaleDataError",
    "RoyaleNotInstalledError",
    "copy_roypy_raw_data",
    "royale_available",
    "royale_to_raw_frame",
    "split_raw_buffer",
]


class RoyaleNotInstalledError(CameraError):
    """The royale SDK's Python module ``roypy`` cannot be imported."""


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


class RoyaleCamera(SourceCamera):
    """A pico flexx streamed through royale in this process
    (:class:`~drivers.camera.source_camera.SourceCamera` over
    :class:`toftwin_camera_bridge.RoyaleSource`).

    Parameters
    ----------
    camera_id : str or None
        royale camera id (``getConnectedCameraList()``); the first camera when None.
    access_code : str or None
        royale access code (level 2, needed for raw data before royale 5); the environment
        variable ``TOFTWIN_ROYALE_ACCESS_CODE`` when None.
    use_case, frame_timeout_s, queue_size, value_shift, mode
        As for :class:`~drivers.camera.source_camera.SourceCamera`.
    """

    def __init__(self, camera_id: str | None = None, *,
                 use_case: str | UseCase = "MODE_5_45FPS_500", access_code: str | None = None,
                 frame_timeout_s: float = 2.0, queue_size: int = 8,
                 value_shift: int = 0, mode: str = "raw") -> None:
        super().__init__(camera_id, use_case=use_case, frame_timeout_s=frame_timeout_s,
                         queue_size=queue_size, value_shift=value_shift, mode=mode)
        self.access_code = access_code

    def _make_source(self) -> RoyaleSource:
        return RoyaleSource(require_roypy(), self._on_frame, self.access_code)

    def _who(self) -> str:
        return f"royale {super()._who()}"
