"""The simulated camera as a camera-bridge source: the bridge's protocol, our simulated world.

:class:`SimulatedCameraSource` has the methods of :class:`toftwin_camera_bridge.RoyaleSource`, so
a :class:`toftwin_camera_bridge.BridgeServer` serves it exactly as it serves a pico flexx through
roypy: each frame is rendered by the same frame source as the simulated USB camera's
(:class:`drivers.sim.usb_camera.CameraRequest` in, :class:`~sim_core.raw.RawFrame` out), from
the physical state of the simulated turntable and lamp, and handed on as the raw data royale
would give (:func:`drivers.camera.royale_convert.raw_frame_to_royale`: 12-bit words, grey first
or last, frequencies and exposures per exposure group, the illumination temperature).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from typing import Any

from drivers.camera.royale_convert import raw_frame_to_royale, raw_frame_to_royale_depth
from drivers.camera.wire import USE_CASES, UseCase, get_use_case
from drivers.sim.usb_camera import CameraRequest
from toftwin_camera_bridge import MODES, BridgeError, RawDataCopy

__all__ = ["SIMULATED_CAMERA_ID", "SimulatedCameraSource"]

#: the id the simulated camera reports (royale's ids look like ``0005-1111-2222-3333``)
SIMULATED_CAMERA_ID = "sim-0001"


class SimulatedCameraSource:
    """A simulated pico flexx behind the camera bridge (module docstring).

    Parameters
    ----------
    on_frame : callable
        Receives each frame's :class:`~toftwin_camera_bridge.RawDataCopy` (the bridge's queue).
    frame_source : callable
        ``CameraRequest -> RawFrame``, as for :class:`drivers.sim.usb_camera.UsbCameraSim`.
    state_provider : callable or None
        The rig state each frame is rendered in (the simulated devices' physical state).
    seed : int
        Noise seed (frame k of a seed is the same whenever drawn).
    grey_last : bool
        Deliver the grey raw frame after the phase frames (royale's other order).
    paced : bool
        Deliver at the use case's frame rate (else as fast as frames render).
    """

    backend = "simulated"

    def __init__(self, on_frame: Callable[[RawDataCopy], None],
                 frame_source: Callable[[CameraRequest], Any],
                 state_provider: Callable[[], Any] | None = None, *, seed: int = 0,
                 grey_last: bool = False, paced: bool = False) -> None:
        self.on_frame = on_frame
        self.frame_source = frame_source
        self.state_provider = state_provider
        self.seed = seed
        self.grey_last = grey_last
        self.paced = paced
        self.callback_errors: list[str] = []
        self.camera_id: str | None = None
        self.use_case: UseCase = USE_CASES["MODE_5_45FPS_500"]
        self.exposure_us: int | None = None
        self.streaming = False
        self.frames_sent = 0
        self._sequence = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.extra: dict[str, Any] = {}
        #: royale's raw data or its processed depth (``open``)
        self.mode = "raw"

    def attach_world(self, url: str) -> None:
        """Film the simulated world served at ``url``
        (:class:`drivers.sim.world_link.WorldLinkServer`): its frame source and rig state."""
        from drivers.sim.world_link import RemoteFrameSource

        old = self.frame_source
        self.frame_source, self.state_provider = RemoteFrameSource(url), None
        if isinstance(old, RemoteFrameSource):
            old.close()

    def describe(self) -> dict[str, Any]:
        return {"backend": self.backend, "royale": None, **self.extra}

    def list_cameras(self) -> list[str]:
        return [SIMULATED_CAMERA_ID]

    def open(self, camera_id: str | None = None, mode: str = "raw") -> dict[str, Any]:
        if camera_id not in (None, SIMULATED_CAMERA_ID):
            raise BridgeError(f"camera {camera_id!r} not among {[SIMULATED_CAMERA_ID]}",
                              "not_found")
        if mode not in MODES:
            raise BridgeError(f"mode {mode!r}; allowed: {', '.join(MODES)}", "input")
        self.mode = mode
        self.camera_id = SIMULATED_CAMERA_ID
        return self.identity()

    def identity(self) -> dict[str, Any]:
        if self.camera_id is None:
            raise BridgeError("no camera is open", "not_found")
        return {"id": self.camera_id, "name": "simulated pico flexx",
                "use_cases": self.use_cases(), "info": {"SIMULATED": "yes"}, "mode": self.mode,
                **self.describe()}

    def use_cases(self) -> list[str]:
        return list(USE_CASES)

    def set_use_case(self, name: str) -> None:
        if name not in USE_CASES:
            raise BridgeError(f"{name!r} is not offered by this camera; it offers "
                              f"{list(USE_CASES)}", "input")
        was = self.streaming
        self.stop()
        self.use_case = get_use_case(name)
        if was:
            self.start()

    def set_exposure(self, exposure_us: int) -> None:
        """Check and keep the exposure asked for; the simulated frames are still rendered at the
        use case's own exposure (the frame source knows no other: issue 28, left open)."""
        if not 1 <= int(exposure_us) <= round(self.use_case.exposure_s * 1e6):
            raise BridgeError(f"exposure {exposure_us} us; 1..{self.use_case.exposure_s * 1e6:g} "
                              f"us for {self.use_case.name}", "input")
        self.exposure_us = int(exposure_us)

    def start(self) -> None:
        if self.streaming:
            return
        self._stop.clear()
        self.streaming = True
        self._thread = threading.Thread(target=self._run, name="sim-bridge-camera", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self.streaming = False
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=30.0)

    def depth_intrinsics(self, uc: UseCase) -> Any:
        """The lens royale's processed depth is computed with, in depth mode: the pico
        flexx's nominal lens (:data:`sim_core.camera.CAMERA_PRESETS`) at the use case's size; a
        real royale applies its camera's own calibration."""
        from sim_core.camera import CAMERA_PRESETS, Intrinsics

        p = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
        return Intrinsics(uc.width, uc.height, p["fx_px"], p["fy_px"], p["cx_px"], p["cy_px"],
                          tuple(p.get("distortion", (0.0,) * 5)))

    def is_connected(self) -> bool:
        return self.camera_id is not None

    def close(self) -> None:
        self.stop()
        self.camera_id = None

    def _run(self) -> None:
        period_s = 1.0 / self.use_case.frame_rate_hz
        uc = self.use_case
        while not self._stop.is_set():
            started = time.monotonic()
            try:
                state = self.state_provider() if self.state_provider is not None else None
                request = CameraRequest(uc, self._sequence, self.seed, time.time(), state)
                self._sequence += 1
                raw = self.frame_source(request)
                data = (raw_frame_to_royale_depth(raw, self.depth_intrinsics(uc))
                        if self.mode == "depth" else
                        raw_frame_to_royale(raw, uc, grey_last=self.grey_last))
            except Exception as exc:  # a failing render is counted; the stream goes on
                self.callback_errors.append(repr(exc))
                self._stop.wait(period_s)
                continue
            if self._stop.is_set():
                return
            with contextlib.suppress(Exception):
                self.on_frame(data)
                self.frames_sent += 1
            if self.paced:
                self._stop.wait(max(0.0, period_s - (time.monotonic() - started)))
