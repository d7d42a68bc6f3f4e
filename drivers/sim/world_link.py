"""The simulated world's frames over TCP, for a simulated camera in another process.

A real camera bridge runs beside the camera; the simulated one (``toftwin camera-bridge
--simulated``) runs beside nothing: the world it films (the scene, the reality, the lab's clock,
the turntable and lamp) is the service's simulated lab. :class:`WorldLinkServer` lets it film
that very world: the service serves its simulated camera's frame source on a loopback port, and
the bridge's :class:`~drivers.sim.bridge_source.SimulatedCameraSource`, once the service's
camera client has attached it (``attach_world``), asks :class:`RemoteFrameSource` for each frame.
A frame through the bridge is then the frame the in-process camera would have rendered for the
same request (same seed and index, the same rig state), and killing the bridge loses no world.

The framing is the camera bridge's (:func:`toftwin_camera_bridge.encode_message`); a request is
``{"op": "render", "use_case": NAME, "frame_index": N, "seed": S, "timestamp_s": T}``, a reply
``{"op": "frame", ...}`` with the :class:`~sim_core.raw.RawFrame`'s arrays as the payload
(phase images and intensity float32, saturated and SBI-limit masks as bytes) or ``{"op":
"error", "message": M}``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import socket
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from drivers.camera.wire import get_use_case
from drivers.sim.usb_camera import CameraRequest
from sim_core.raw import RawFrame
from toftwin_camera_bridge import BridgeError, encode_message, read_message

__all__ = ["RemoteFrameSource", "WorldLinkServer"]

_log = logging.getLogger(__name__)


def _json_safe(meta: dict[str, Any]) -> dict[str, Any]:
    """The frame's metadata that JSON can carry (the rest is dropped, not garbled)."""
    out: dict[str, Any] = {}
    for key, value in meta.items():
        with contextlib.suppress(TypeError, ValueError):
            json.dumps(value)
            out[str(key)] = value
    return out


class WorldLinkServer:
    """Serve ``frame_source`` (``CameraRequest -> RawFrame``) with ``state_provider``'s rig
    state to simulated cameras in other processes (module docstring)."""

    def __init__(self, frame_source: Callable[[CameraRequest], RawFrame],
                 state_provider: Callable[[], Any] | None, host: str = "127.0.0.1",
                 port: int = 0) -> None:
        self.frame_source = frame_source
        self.state_provider = state_provider
        self._listener = socket.create_server((host, port))
        self.address: tuple[str, int] = self._listener.getsockname()[:2]
        self._stop = threading.Event()
        self.frames_served = 0

    @property
    def url(self) -> str:
        return f"tcp://{self.address[0]}:{self.address[1]}"

    def start(self) -> WorldLinkServer:
        threading.Thread(target=self._accept_loop, name="world-link", daemon=True).start()
        return self

    def close(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self._listener.close()

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), name="world-link-client",
                             daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn:
            while not self._stop.is_set():
                try:
                    message, _ = read_message(conn)
                except (ConnectionError, OSError, BridgeError):
                    return
                try:
                    reply, payload = self._render(message)
                except Exception as exc:  # the renderer's failure goes to the camera's side
                    reply, payload = {"op": "error", "message": repr(exc)}, b""
                try:
                    conn.sendall(encode_message(reply, payload))
                except OSError:
                    return

    def _render(self, message: dict[str, Any]) -> tuple[dict[str, Any], bytes]:
        if message.get("op") != "render":
            raise BridgeError(f"unknown op {message.get('op')!r}", "protocol")
        state = self.state_provider() if self.state_provider is not None else None
        request = CameraRequest(get_use_case(str(message["use_case"])),
                                int(message["frame_index"]), int(message["seed"]),
                                float(message.get("timestamp_s", 0.0)), state)
        raw = self.frame_source(request)
        self.frames_served += 1
        phases = np.ascontiguousarray(raw.phase_images, dtype="<f4")
        grey = np.ascontiguousarray(raw.intensity, dtype="<f4")
        masks = np.stack([raw.saturated, raw.sbi_limit]).astype(np.uint8)
        reply = {"op": "frame", "phase_shape": list(phases.shape),
                 "frequencies_hz": [float(f) for f in raw.frequencies_hz],
                 "exposure_s": float(raw.exposure_s), "timestamp_s": float(raw.timestamp_s),
                 "illumination_temperature_c": raw.illumination_temperature_c,
                 "meta": _json_safe(raw.meta)}
        return reply, phases.tobytes() + grey.tobytes() + masks.tobytes()


class RemoteFrameSource:
    """A frame source (``CameraRequest -> RawFrame``) rendered by a :class:`WorldLinkServer` at
    ``url`` (``tcp://HOST:PORT``); the request's own rig state is not sent: the world's is used.
    """

    def __init__(self, url: str, timeout_s: float = 600.0) -> None:
        from drivers.camera.bridge_client import parse_bridge_url

        self.url = url
        self.host, self.port = parse_bridge_url(url)
        self.timeout_s = timeout_s
        self._sock: socket.socket | None = None
        self._lock = threading.Lock()

    def __call__(self, request: CameraRequest) -> RawFrame:
        with self._lock:
            try:
                return self._render(request)
            except (OSError, ConnectionError) as exc:
                self.close()
                raise BridgeError(f"simulated world at {self.url}: {exc}",
                                  "disconnected") from exc

    def _render(self, request: CameraRequest) -> RawFrame:
        if self._sock is None:
            self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        self._sock.sendall(encode_message({
            "op": "render", "use_case": request.use_case.name,
            "frame_index": request.frame_index, "seed": request.seed,
            "timestamp_s": request.timestamp_s}))
        reply, payload = read_message(self._sock)
        if reply["op"] != "frame":
            raise BridgeError(f"simulated world at {self.url}: {reply.get('message')}")
        n_f, n_p, height, width = reply["phase_shape"]
        n_phase = n_f * n_p * height * width
        expected = 4 * n_phase + 4 * height * width + 2 * height * width
        if len(payload) != expected:
            raise BridgeError(f"simulated world at {self.url}: frame payload of {len(payload)} "
                              f"bytes; {expected} expected", "protocol")
        phases = np.frombuffer(payload, "<f4", n_phase).reshape(n_f, n_p, height, width)
        grey = np.frombuffer(payload, "<f4", height * width, 4 * n_phase).reshape(height, width)
        masks = np.frombuffer(payload, np.uint8, offset=4 * n_phase + 4 * height * width)
        masks = masks.reshape(2, height, width).astype(bool)
        return RawFrame(
            phase_images=phases.astype(np.float32), intensity=grey.astype(np.float32),
            frequencies_hz=np.asarray(reply["frequencies_hz"], dtype=np.float64),
            saturated=masks[0], sbi_limit=masks[1], exposure_s=float(reply["exposure_s"]),
            timestamp_s=float(reply["timestamp_s"]), meta=dict(reply.get("meta") or {}),
            illumination_temperature_c=reply.get("illumination_temperature_c"))

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.close()
