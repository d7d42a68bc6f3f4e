"""The ToF camera as an ophyd-async ``StandardDetector`` writing its frames as NeXus HDF5.

:class:`ToFCamera` wraps a camera driver (:class:`~drivers.camera.CameraProtocol`: the USB
driver :class:`~drivers.camera.UsbCamera`, royale's, a camera bridge's). ophyd-async splits a
detector into logics; ours are:

- trigger logic: internal triggering only, one raw frame an exposure at the use case's own
  exposure (a ``livetime`` other than 0 is refused: the exposure is the use case's);
- acquire logic: each exposure is one ``capture(1)`` of the driver, run in a worker thread
  under the device's lock (:class:`drivers.bluesky.calls.DriverCalls`); a trigger returns once
  its frame is written, and fails with the driver's own error when the capture fails;
- data logic: one HDF5 file per run where the path provider says, a
  :class:`sim_core.nexus.NexusFrameStack` (``/entry/depth/data`` is (frame, y, x) ...;
  docs/export-hdf5.md). Every captured raw frame is reconstructed with the camera model's
  intrinsics (:func:`sim_core.frame_io.measured_frame`, as the service stores a measured frame)
  and appended, flushed, before the frame counts as written. The run's documents announce the
  file in one StreamResource per dataset (mimetype ``application/x-hdf5``, parameters
  ``dataset`` and ``chunk_shape``, data key ``<name>-<group>``: ``camera-depth``, ...) and each
  event's frames in a StreamDatum (indices along the frame axis), as ophyd-async's HDF writers
  do: Tiled's HDF5 consolidator and any h5py reader follow them (docs/export-bluesky.md).

The frames the camera returned are handed, with their index in the file, to ``on_frame``
(called in the worker thread after the append), e.g. to check or show them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from ophyd_async.core import (
    DetectorAcquireLogic,
    DetectorDataLogic,
    DetectorTriggerLogic,
    PathProvider,
    StandardDetector,
    StreamableDataProvider,
    StreamResourceDataProvider,
    StreamResourceInfo,
    TriggerInfo,
    soft_signal_r_and_setter,
)

from drivers.bluesky.calls import DriverCalls, Hold
from drivers.camera import CameraProtocol, UseCase
from drivers.rig import RigState
from sim_core.camera import CAMERA_PRESETS, Camera, Intrinsics
from sim_core.frame_io import Frame, measured_frame
from sim_core.nexus import HDF5_MIMETYPE, IMAGE_GROUPS, NexusFrameStack
from sim_core.raw import RawFrame

__all__ = ["FrameDataset", "NexusFrameWriter", "ToFCamera", "frame_datasets",
           "preset_camera"]

_log = logging.getLogger(__name__)

#: while a frame is being captured (a simulated one is path traced), the frame count is
#: re-announced this often [s], so that a watcher's wait for the next update (ophyd-async's
#: exposure timeout, 10 s by default) does not run out during one long frame
HEARTBEAT_S = 1.0
#: the camera preset a camera model is made from when none is given
PRESET = "pmd-camboard-pico-flexx"
#: what a camera model may be given as: the model, or the model for a use case
CameraModel = Camera | Callable[[UseCase], Camera]
#: ``on_frame(index, raw, frame)``: the frame's index in the file, what the camera returned,
#: its reconstruction as written
OnFrame = Callable[[int, RawFrame, Frame], None]


@dataclass(frozen=True)
class FrameDataset:
    """One dataset of the frames' file: its group, path, one frame's shape and dtype."""

    group: str
    dataset: str
    shape: tuple[int, ...]
    dtype: np.dtype


def frame_datasets(use_case: UseCase, raw: bool = True) -> list[FrameDataset]:
    """The datasets a frame of ``use_case`` adds to a :class:`~sim_core.nexus.NexusFrameStack`:
    the (H, W) images, ``phase`` (n_f, H, W) and, for a raw frame, ``raw`` (n_f, 4, H, W).

    >>> from drivers.camera import get_use_case
    >>> [(d.dataset, d.shape, d.dtype.str) for d in frame_datasets(
    ...     get_use_case("MODE_5_45FPS_500"))][::3]
    [('/entry/depth/data', (171, 224), '<f8'), ('/entry/amplitude/data', (171, 224), '<f8'),
     ('/entry/phase/data', (1, 171, 224), '<f8')]
    """
    h, w = use_case.shape
    n_f = len(use_case.frequencies_hz)
    small = {"grey": np.uint8, "valid": np.uint8}
    out = [FrameDataset(g, f"/entry/{g}/data", (h, w), np.dtype(small.get(g, np.float64)))
           for g in IMAGE_GROUPS]
    out.append(FrameDataset("phase", "/entry/phase/data", (n_f, h, w), np.dtype(np.float64)))
    if raw:
        out.append(FrameDataset("raw", "/entry/raw/data", (n_f, 4, h, w), np.dtype(np.float32)))
    return out


def preset_camera(use_case: UseCase) -> Camera:
    """The pico flexx preset's camera model at ``use_case``'s image size (the principal point
    at the image centre where the size is not the preset's), for reconstructing its frames."""
    p = CAMERA_PRESETS[PRESET]
    h, w = use_case.shape
    same = (w, h) == (p["width_px"], p["height_px"])
    intr = Intrinsics(w, h, p["fx_px"], p["fy_px"], p["cx_px"] if same else (w - 1) / 2.0,
                      p["cy_px"] if same else (h - 1) / 2.0)
    return Camera(intr, np.eye(4), modulation_frequencies_hz=tuple(use_case.frequencies_hz),
                  exposure_s=use_case.exposure_s, preset=PRESET)


class NexusFrameWriter:
    """Captures frames with a camera driver into a :class:`~sim_core.nexus.NexusFrameStack`;
    :attr:`frames_written` counts the frames in the open file.

    Parameters
    ----------
    camera : CameraProtocol
    calls : DriverCalls
        How the driver is called (worker thread, lock).
    camera_model : Camera or callable or None
        Intrinsics the frames are reconstructed with: a model, a function of the use case, or
        None for :func:`preset_camera`.
    rig_state : callable or None
        The rig's state, read (under the same lock) before each capture and written with the
        frame (``/entry/rig``); None: only what the camera reports.
    on_frame : callable or None
        ``on_frame(index, raw, frame)`` after each frame is written (in the worker thread).
    """

    def __init__(self, camera: CameraProtocol, calls: DriverCalls,
                 camera_model: CameraModel | None = None,
                 rig_state: Callable[[], RigState] | None = None,
                 on_frame: OnFrame | None = None) -> None:
        self.camera = camera
        self.calls = calls
        self.camera_model = camera_model
        self.rig_state = rig_state
        self.on_frame = on_frame
        self.frames_written, self._set_written = soft_signal_r_and_setter(int, 0)
        self.path: Path | None = None
        self._stack: NexusFrameStack | None = None
        self._count = 0
        #: the open stack: appended to in a worker thread, closed from the event loop's
        self._lock = threading.Lock()

    @property
    def raw(self) -> bool:
        """The camera delivers raw frames (not royale's processed depth, which has no raw
        phase images)."""
        return getattr(self.camera, "mode", "raw") == "raw"

    def model_for(self, use_case: UseCase) -> Camera:
        model = self.camera_model
        if model is None:
            return preset_camera(use_case)
        return model if isinstance(model, Camera) else model(use_case)

    # -- the file -----------------------------------------------------------------------------
    def _open(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with self._lock:
            if self._stack is not None:
                self._stack.close()
                self._stack = None
            try:
                stack = NexusFrameStack(path, replace=False)
            except FileExistsError:
                raise FileExistsError(
                    f"{path} exists: the camera does not write a run's frames over an earlier "
                    "file (whose run's documents point into it); give each run a file of its "
                    "own (ophyd-async's UUIDFilenameProvider or AutoIncrementFilenameProvider)"
                ) from None
            self._stack, self.path, self._count = stack, path, 0

    async def open(self, path: Path) -> list[FrameDataset]:
        """Start a new file at ``path`` (an existing one is refused: it may be an earlier
        run's); returns the datasets its frames will have (for the use case the camera is
        configured with now)."""
        use_case = await self.calls(lambda: self.camera.use_case)
        await asyncio.to_thread(self._open, Path(path))
        self._set_written(0)
        return frame_datasets(use_case, raw=self.raw)

    def _close(self) -> None:
        with self._lock:
            if self._stack is not None:
                self._stack.close()
                self._stack = None

    async def close(self) -> None:
        """Close the file (waiting for a frame being appended); safe to call twice."""
        await asyncio.to_thread(self._close)

    # -- capturing ------------------------------------------------------------------------
    def _capture_one(self) -> int:
        """Capture, reconstruct and append one frame (worker thread, under the lock of
        :attr:`calls`); returns the number of frames in the file."""
        state = self.rig_state() if self.rig_state is not None else None
        raw = self.camera.capture(1)[0]
        use_case = self.camera.use_case
        extra: dict[str, Any] = {"use_case": use_case.name, "scene_name": ""}
        if state is not None:
            extra["rig"] = state.to_dict()
        frame = measured_frame(raw, self.model_for(use_case), extra)
        with self._lock:
            if self._stack is None:
                raise RuntimeError("the camera's file was closed while a frame was captured "
                                   "(the run ended); the frame is not written")
            index = self._stack.append(frame)
            self._count = self._stack.count
            count = self._count
        if self.on_frame is not None:
            self.on_frame(index, raw, frame)
        return count

    async def _heartbeat(self, task: asyncio.Future[int]) -> int:
        try:
            while True:
                done, _ = await asyncio.wait({task}, timeout=HEARTBEAT_S)
                if done:
                    return task.result()
                self._set_written(self._count)  # the same count: a sign of life (HEARTBEAT_S)
        except asyncio.CancelledError:
            # the run stopped: the frame being captured is not written (the file is closed),
            # and what its worker thread returns is not waited for
            task.cancel()
            raise

    async def capture(self, n: int, first_written: asyncio.Event) -> None:
        """Capture ``n`` frames (0: until cancelled) one by one; :attr:`frames_written` and
        ``first_written`` follow."""
        i = 0
        while n == 0 or i < n:
            count = await self._heartbeat(asyncio.ensure_future(self.calls(self._capture_one)))
            self._set_written(count)
            first_written.set()
            i += 1


class _Trigger(DetectorTriggerLogic):
    """Internal triggering at the use case's exposure; remembers how many exposures."""

    def __init__(self, camera: CameraProtocol, calls: DriverCalls, name: Callable[[], str]):
        self.camera, self.calls, self.name = camera, calls, name
        self.exposures = 1

    async def prepare_internal(self, num: int, livetime: float, deadtime: float) -> None:
        if livetime != 0.0:
            use_case = await self.calls(lambda: self.camera.use_case)
            raise ValueError(
                f"{self.name()}: livetime {livetime:g} s asked; the camera's exposure is its use "
                f"case's ({use_case.name}: {use_case.exposure_s * 1e6:g} us per phase step): "
                "give livetime 0, or configure another use case")
        self.exposures = num

    async def default_trigger_info(self) -> TriggerInfo:
        return TriggerInfo()


class _Acquire(DetectorAcquireLogic):
    """Captures the prepared number of frames in a task; a start returns once the first frame
    is written (or raises the capture's error)."""

    def __init__(self, writer: NexusFrameWriter, trigger: _Trigger) -> None:
        self.writer, self.trigger = writer, trigger
        self.task: asyncio.Task[None] | None = None

    async def start_acquiring(self) -> None:
        if self.task is not None and not self.task.done():
            # a kickoff while the prepared frames are still being captured: they are the ones
            # it asks for (ophyd-async refuses a kickoff beyond what was prepared)
            return
        first = asyncio.Event()
        self.task = asyncio.create_task(self.writer.capture(self.trigger.exposures, first))
        waiter = asyncio.create_task(first.wait())
        try:
            await asyncio.wait({self.task, waiter}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiter.cancel()
        if self.task.done():
            self.task.result()  # the capture's own error, if it failed

    async def wait_for_idle(self) -> None:
        if self.task is not None:
            await self.task

    async def ensure_stopped(self) -> None:
        task, self.task = self.task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            try:
                await task
            except Exception as exc:  # raised where it happened (a trigger, a complete)
                _log.debug("camera acquisition ended with %s: %s", type(exc).__name__, exc)


class _NexusData(DetectorDataLogic):
    """One NeXus file per run; a StreamResource per dataset, StreamDatum per event."""

    def __init__(self, writer: NexusFrameWriter, path_provider: PathProvider) -> None:
        self.writer, self.path_provider = writer, path_provider

    async def prepare_unbounded(self, datakey_name: str) -> StreamableDataProvider:
        info = self.path_provider(datakey_name)
        filename = f"{info.filename}.h5"
        datasets = await self.writer.open(Path(info.directory_path) / filename)
        resources = [
            StreamResourceInfo(data_key=f"{datakey_name}-{d.group}", shape=d.shape,
                               chunk_shape=(1, *d.shape), dtype_numpy=d.dtype.str,
                               parameters={"dataset": d.dataset})
            for d in datasets
        ]
        return StreamResourceDataProvider(
            uri=f"{info.directory_uri}{filename}", resources=resources, mimetype=HDF5_MIMETYPE,
            collections_written_signal=self.writer.frames_written)

    async def stop(self) -> None:
        await self.writer.close()

    def get_hinted_fields(self, datakey_name: str) -> Sequence[str]:
        return [f"{datakey_name}-depth"]


class ToFCamera(StandardDetector):
    """The ToF camera as an ophyd-async detector whose frames go to a NeXus HDF5 file.

    Parameters
    ----------
    driver : CameraProtocol
        A connected camera driver.
    path_provider : PathProvider
        Where each run's file goes (ophyd-async's ``StaticPathProvider`` and friends); the
        file is ``<directory>/<filename>.h5``.
    camera_model : Camera or callable or None
        The intrinsics frames are reconstructed with (the scene's camera, a calibration's), or a
        function of the use case giving them; None: the pico flexx preset at the use case's
        size (:func:`preset_camera`).
    hold : callable or None
        Held around every driver call (the rig's :meth:`~drivers.rig.Rig.hold` for the
        devices of one rig).
    rig_state : callable or None
        Read before each capture and written with the frame (``/entry/rig``).
    on_frame : callable or None
        ``on_frame(index, raw, frame)`` after each frame is written.
    name : str

    Configuration: ``-use_case`` (royale's name) and ``-exposure_s`` (per phase step).
    """

    def __init__(self, driver: CameraProtocol, path_provider: PathProvider, *,
                 camera_model: CameraModel | None = None, hold: Hold | None = None,
                 rig_state: Callable[[], RigState] | None = None,
                 on_frame: OnFrame | None = None, name: str = "") -> None:
        self.driver = driver
        self.calls = DriverCalls(hold)
        self.writer = NexusFrameWriter(driver, self.calls, camera_model, rig_state, on_frame)
        self.frames_written = self.writer.frames_written
        self.use_case, _ = soft_signal_r_and_setter(
            str, getter=partial(self.calls, lambda: driver.use_case.name))
        self.exposure_s, _ = soft_signal_r_and_setter(
            float, units="s", getter=partial(self.calls, lambda: driver.use_case.exposure_s))
        trigger = _Trigger(driver, self.calls, lambda: self.name or "camera")
        self.add_detector_logics(trigger, _Acquire(self.writer, trigger),
                                 _NexusData(self.writer, path_provider))
        self.add_config_signals(self.use_case, self.exposure_s)
        super().__init__(name=name)
