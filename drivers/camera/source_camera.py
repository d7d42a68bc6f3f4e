"""A camera fed by a source of royale raw data: in this process or through the camera bridge.

:class:`SourceCamera` implements :class:`~drivers.camera.protocol.CameraProtocol` over a *source*
with the methods of :class:`toftwin_camera_bridge.RoyaleSource` (``open``, ``identity``,
``use_cases``, ``set_use_case``, ``set_exposure``, ``start``, ``stop``, ``is_connected``,
``close``) that hands every frame to a callback as a :class:`~toftwin_camera_bridge.RawDataCopy`:
royale's own source in this process (:class:`drivers.camera.royale.RoyaleCamera`) or the same
source on another PC through the bridge (:class:`drivers.camera.bridge_client.BridgeCamera`).
One capture logic and one conversion (:func:`drivers.camera.royale.royale_to_raw_frame`) for both.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import time
from typing import Any

from drivers.camera.protocol import (
    CameraError,
    CameraIdentity,
    CameraLostError,
    CameraNotFoundError,
)
from drivers.camera.royale_convert import (
    RoyaleDataError,
    royale_depth_to_frame,
    royale_to_raw_frame,
)
from drivers.camera.wire import UseCase, get_use_case
from drivers.errors import DeviceInputError, DeviceTimeoutError
from sim_core.processed_depth import ProcessedDepthFrame
from sim_core.raw import RawFrame
from toftwin_camera_bridge import (
    MODES,
    BridgeError,
    DepthDataCopy,
    RawDataCopy,
    put_dropping_oldest,
)

__all__ = ["SourceCamera", "camera_error"]

_log = logging.getLogger(__name__)

#: how often a capture waiting for a frame asks the source whether the camera is still there [s]
POLL_S = 0.25


def camera_error(exc: BridgeError, who: str) -> Exception:
    """A source's :class:`~toftwin_camera_bridge.BridgeError` as the driver's error family; a
    lost camera or bridge names ``who`` (the camera as :meth:`SourceCamera._who` says it)."""
    if exc.kind == "not_found":
        return CameraNotFoundError(str(exc))
    if exc.kind == "input":
        return DeviceInputError("use_case", str(exc))
    if exc.kind == "disconnected":
        return CameraLostError(f"{who}: {exc}")
    return CameraError(str(exc))


class SourceCamera:
    """A :class:`~drivers.camera.protocol.CameraProtocol` over a raw-data source (module doc).

    Subclasses make the source (:meth:`_make_source`) and name the camera (:meth:`_who`).

    Parameters
    ----------
    camera_id : str or None
        The camera's id at its source; the first camera when None.
    use_case : str
        Use case configured at :meth:`connect`.
    frame_timeout_s : float
        Longest wait for one frame in :meth:`capture`.
    queue_size : int
        Frames buffered between the source's thread and :meth:`capture`; when full the oldest
        is dropped and counted in ``dropped``. Frames of the previous use case that arrive after a
        switch or a reconnection are dropped and counted in ``stale`` (and named when no frame
        of the use case comes).
    value_shift : int
        See :func:`~drivers.camera.royale_convert.royale_to_raw_frame`.
    mode : "raw" or "depth"
        royale's raw data (frames are :class:`~sim_core.raw.RawFrame`), or its processed depth
        for labs without raw access (:class:`~sim_core.processed_depth.ProcessedDepthFrame`).
    """

    backend = "royale"

    def __init__(self, camera_id: str | None = None, *,
                 use_case: str | UseCase = "MODE_5_45FPS_500", frame_timeout_s: float = 2.0,
                 queue_size: int = 8, value_shift: int = 0, mode: str = "raw") -> None:
        if mode not in MODES:
            raise DeviceInputError("camera_mode", f"got {mode!r}; allowed: {', '.join(MODES)}")
        self.mode = mode
        self.camera_id = camera_id
        self._use_case = get_use_case(use_case)
        self.frame_timeout_s = frame_timeout_s
        self.value_shift = value_shift
        self._queue: queue.Queue[tuple[float, RawDataCopy]] = queue.Queue(maxsize=queue_size)
        self._source: Any = None
        self._opened_id: str | None = None
        self.dropped = 0
        self.stale = 0
        #: why the last stale frame was not the configured use case's (the conversion's words)
        self.stale_reason: str | None = None

    # -- what a subclass provides ---------------------------------------------------------------
    def _make_source(self) -> Any:
        raise NotImplementedError

    def _who(self) -> str:
        """The camera as messages name it."""
        return f"camera {self._opened_id or self.camera_id or '(first)'}"

    @property
    def callback_errors(self) -> list[str]:
        """Failures inside the source's callbacks (counted, never raised there)."""
        return [] if self._source is None else self._source.callback_errors

    @property
    def _streaming(self) -> bool:
        return bool(self._source is not None and self._source.streaming)

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the camera at its source and set the use case."""
        if self._source is not None:
            return
        source = self._make_source()
        try:
            identity = source.open(self.camera_id, self.mode)
            served = identity.get("mode", "raw")  # a bridge older than the mode serves raw
            if served != self.mode:
                raise CameraError(
                    f"{self._who()} serves {served} frames, {self.mode} were asked for: this "
                    "camera bridge predates the camera mode; update toftwin_camera_bridge.py "
                    "on the camera's PC")
            self._opened_id = identity.get("id") or self.camera_id
            self._source = source
            self.configure(self._use_case)
        except BridgeError as exc:
            self._abandon(source)
            raise camera_error(exc, self._who()) from exc
        except BaseException:
            self._abandon(source)
            raise

    def _abandon(self, source: Any) -> None:
        self._source = None
        with contextlib.suppress(Exception):
            source.close()

    def _on_frame(self, data: RawDataCopy) -> None:
        """The source's thread: queue the copy (dropping the oldest when full)."""
        self.dropped += put_dropping_oldest(self._queue, (time.time(), data))

    def close(self) -> None:
        """Stop capturing and drop the camera; safe to call twice."""
        source, self._source = self._source, None
        if source is not None:
            with contextlib.suppress(Exception):
                source.close()

    def __enter__(self) -> SourceCamera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _require(self) -> Any:
        if self._source is None:
            self.connect()
        return self._source

    def _do(self, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except BridgeError as exc:
            raise camera_error(exc, self._who()) from exc

    # -- Camera protocol ----------------------------------------------------------------------
    @property
    def use_case(self) -> UseCase:
        return self._use_case

    def configure(self, use_case: str | UseCase) -> None:
        uc = get_use_case(use_case)
        source = self._require()
        self._do(source.set_use_case, uc.name)
        self._use_case = uc
        self._drain()  # frames of the previous use case

    def start(self) -> None:
        self._do(self._require().start)

    def stop(self) -> None:
        if self._source is not None:
            self._do(self._source.stop)

    def _drain(self) -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                self._queue.get_nowait()

    def capture(self, n: int = 1) -> list[RawFrame | ProcessedDepthFrame]:
        """The next ``n`` raw frames converted by
        :func:`~drivers.camera.royale_convert.royale_to_raw_frame` (in depth mode royale's
        processed depth, by :func:`~drivers.camera.royale_convert.royale_depth_to_frame`).

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
        frames: list[RawFrame | ProcessedDepthFrame] = []
        try:
            while len(frames) < n:
                arrived, data = self._next(len(frames), n)
                frame = self._convert(arrived, data)
                if frame is not None:
                    frames.append(frame)
        finally:
            if one_shot and self._source is not None:
                try:
                    self.stop()
                except CameraError as exc:
                    _log.warning("%s: stop after capture failed: %s", self._who(), exc)
        return frames

    def _convert(self, arrived: float,
                 data: RawDataCopy | DepthDataCopy) -> RawFrame | ProcessedDepthFrame | None:
        """One copy as a frame of the configured use case; ``None`` (counted in ``stale``) for a
        well-formed frame of another configuration: one the source took before a use-case switch
        or a reconnection but handed over after it (a source's capture thread and its command
        replies are not ordered). A copy that is no raw frame at all is an error."""
        meta = {"device": self._opened_id or self.camera_id}
        if isinstance(data, DepthDataCopy) != (self.mode == "depth"):
            self.stale += 1  # a frame of the mode before a switch (or a reconnection)
            self.stale_reason = f"a {'depth' if self.mode == 'raw' else 'raw'} frame in " \
                                f"{self.mode} mode"
            return None
        if isinstance(data, DepthDataCopy):
            try:
                return royale_depth_to_frame(data, use_case=self._use_case,
                                             timestamp_s=arrived, meta=meta)
            except RoyaleDataError as exc:
                self.stale += 1
                self.stale_reason = str(exc)
                return None
        try:
            return royale_to_raw_frame(data, use_case=self._use_case, value_shift=self.value_shift,
                                       timestamp_s=arrived, meta=meta)
        except RoyaleDataError as exc:
            royale_to_raw_frame(data, value_shift=self.value_shift, timestamp_s=arrived,
                                meta=meta)  # raises when the copy is malformed in itself
            self.stale += 1
            self.stale_reason = str(exc)
            return None

    def _next(self, got: int, n: int) -> tuple[float, RawDataCopy]:
        """The next queued frame; waits at most ``frame_timeout_s``, and no longer than
        :data:`POLL_S` once the source says the camera is gone."""
        deadline = time.monotonic() + self.frame_timeout_s
        while True:
            try:
                return self._queue.get(timeout=max(0.0, min(POLL_S,
                                                             deadline - time.monotonic())))
            except queue.Empty:
                source = self._source
                gone = False
                with contextlib.suppress(Exception):
                    gone = source is None or not source.is_connected()
                if gone or time.monotonic() >= deadline:
                    raise self._no_frame_error(got, n) from None

    def _no_frame_error(self, got: int, n: int) -> CameraLostError | DeviceTimeoutError:
        """Why no frame came: a disconnected camera (its source says so), else a timeout;
        both name the camera."""
        stale = "" if not self.stale else f" (the last: {self.stale_reason})"
        detail = (f"{got} of {n} frames; {self.stale} of another use case dropped{stale}; "
                  f"callback errors: {self.callback_errors[-3:]}")
        source = self._source
        connected = True
        with contextlib.suppress(Exception):
            connected = source is None or source.is_connected()
        if not connected:
            why = getattr(source, "disconnect_reason", None) or "isConnected() is false"
            return CameraLostError(f"{self._who()}: disconnected ({why}); {detail}")
        return DeviceTimeoutError(
            f"{self._who()}: no raw frame within {self.frame_timeout_s:g} s ({detail})")

    def identity(self) -> CameraIdentity:
        ident = self._do(self._require().identity)
        return CameraIdentity(
            model=ident.get("name") or "royale camera",
            serial=ident.get("id") or (self.camera_id or ""),
            product=ident.get("name"),
            backend=self.backend,
            extra={str(k): str(v) for k, v in (ident.get("info") or {}).items()},
        )
